#include "host/bench/transection_bench.hpp"

#include <algorithm>
#include <cmath>
#include <iostream>

#include "host/cut/transection.hpp"
#include "host/scene/scene.hpp"
#include "host/sim/model_factory.hpp"

namespace arnav::host {

namespace {
double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5))];
}
}  // namespace

int run_transection_bench(const TransectionBenchOptions& options) {
  int failed = 0;
  for (const std::string& path : options.scenes) {
    const Scene loaded = load_scene(path);
    for (const std::string& support : options.supports) {
      Scene sc = loaded;
      if (support == "free") {
        sc.problem.fixed_vertices.clear();
        sc.problem.gravity_World_mm_s2.setZero();
      }
      for (const ModelVariant& variant : model_variants()) {
        if (!options.setting_prefixes.empty() &&
            std::none_of(options.setting_prefixes.begin(), options.setting_prefixes.end(),
                         [&](const std::string& p) { return variant.label.rfind(p, 0) == 0; }))
          continue;
        cut::TransectionSettings settings;
        settings.threads = options.threads;
        const bool held = support == "held";  // as cut_transection_test
        settings.settle_s = held ? 0.5 : 0.0;
        settings.margin_mm = options.margin_mm;
        settings.stroke_s = 0.4;
        settings.after_s = 0.3;
        settings.return_stroke = held;
        const cut::TransectionResult r = cut::run_transection(sc, variant, settings);
        double worst_side = 0.0;
        for (int s = 0; s < 2; ++s)
          worst_side = std::max(worst_side, std::abs(r.side_volume_mm3[s] / std::max(r.expected_side_volume_mm3[s], 1e-12) - 1.0));
        const bool ok = r.unhealthy_steps == 0 && r.finite && r.mesh_valid && worst_side <= (support == "free" ? 1e-4 : 5e-2);
        failed += ok ? 0 : 1;
        std::string warning = r.first_unhealthy.substr(0, 300);
        std::replace(warning.begin(), warning.end(), '"', '\'');
        std::cout << "{\"scene\":\"" << path << "\",\"tets\":" << sc.problem.mesh.num_tets() << ",\"support\":\"" << support
                  << "\",\"model\":\"" << variant.label << "\",\"frames\":" << r.frames << ",\"unhealthy_steps\":" << r.unhealthy_steps
                  << ",\"refused\":" << r.refused << ",\"mesh_valid\":" << (r.mesh_valid ? "true" : "false") << ",\"tets_cut\":" << r.tets_cut
                  << ",\"pieces\":" << r.pieces << ",\"pieces_after_first_stroke\":" << r.pieces_after_first_stroke << ",\"side_volume_rel_error\":" << worst_side << ",\"peak_inverted\":" << r.peak_inverted
                  << ",\"frames_with_inverted\":" << r.frames_with_inverted << ",\"step_median_ms\":" << percentile(r.step_ms, 0.5)
                  << ",\"step_p99_ms\":" << percentile(r.step_ms, 0.99) << ",\"frame_median_ms\":" << percentile(r.frame_ms, 0.5)
                  << ",\"frame_p99_ms\":" << percentile(r.frame_ms, 0.99) << ",\"ok\":" << (ok ? "true" : "false")
                  << ",\"first_unhealthy\":\"" << warning << "\"}" << std::endl;
      }
    }
  }
  return failed;
}

}  // namespace arnav::host
