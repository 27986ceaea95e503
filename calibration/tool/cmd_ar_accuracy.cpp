// arnav-calib ar-accuracy: paper 000's AR error per view angle, from bench measurements
// or from the end-to-end simulation of the chain (the benchmark).
#include <cmath>
#include <iostream>
#include <memory>

#include <nlohmann/json.hpp>

#include "calibration/lib/ar_accuracy.hpp"
#include "calibration/vision/ar_chain_sim.hpp"
#include "calibration/lib/calib_error.hpp"
#include "calibration/tool/commands.hpp"
#include "calibration/tool/report.hpp"

namespace arnav::calib::tool {

namespace {
struct ArArgs {
  std::string measurements, out = ".", chain = "marker", method = "axzb-shah";
  bool simulate = false, render = false;
  double render_noise = 2.0, render_blur = 0.5;
  int runs = 10, trials = 5;
  double ndi_mm = 0.25, corner_px = 0.2, target_mm = 1.0;
  std::uint64_t seed = 1;
};
}  // namespace

Run add_ar_accuracy_command(CLI::App& app) {
  auto a = std::make_shared<ArArgs>();
  CLI::App* c = app.add_subcommand("ar-accuracy", "AR error per view angle (paper 000): from measurements or --simulate");
  auto* m = c->add_option("--measurements", a->measurements,
                          "CSV: view_angle_deg, virtual x y z, realigned x y z (mm, tracker frame), one trial per line");
  auto* s = c->add_flag("--simulate", a->simulate, "simulate the full chain with bench noise (benchmark)");
  m->excludes(s);
  c->add_option("--runs", a->runs, "simulation: calibration sessions")->capture_default_str();
  c->add_option("--trials", a->trials, "simulation: trials per view angle per session")->capture_default_str();
  c->add_option("--ndi-noise", a->ndi_mm, "simulation: NDI sphere noise, mm RMS (3D)")->capture_default_str();
  c->add_option("--corner-noise", a->corner_px, "simulation: corner noise, px per axis")->capture_default_str();
  c->add_option("--chain", a->chain, "simulation: marker (paper 000) or direct (via X_CamNdi)")
      ->check(CLI::IsMember({"marker", "direct"}))->capture_default_str();
  c->add_option("--method", a->method, "simulation: hand-eye method")->capture_default_str();
  c->add_option("--seed", a->seed, "simulation: random seed")->capture_default_str();
  c->add_flag("--render", a->render, "simulation: render every view with the synthetic camera and detect the tags "
                                     "(slow; --corner-noise is then unused)");
  c->add_option("--render-noise", a->render_noise, "simulation --render: sensor noise, gray levels")->capture_default_str();
  c->add_option("--render-blur", a->render_blur, "simulation --render: blur sigma, px")->capture_default_str();
  c->add_option("--target-mm", a->target_mm, "reference line on the plot (the benchmark target)")->capture_default_str();
  c->add_option("--out", a->out, "output folder")->capture_default_str();
  return [a] {
    if (a->measurements.empty() && !a->simulate) throw CalibError("ar-accuracy: give --measurements FILE or --simulate");
    const auto dir = prepare_out_dir(a->out);
    Report r(dir, "ar-accuracy");
    std::vector<ArTrial> trials;
    std::vector<ArAngleStats> stats;
    nlohmann::json j;
    if (a->simulate) {
      ArSimOptions o;
      o.runs = a->runs;
      o.trials_per_angle = a->trials;
      o.ndi_rms_mm = a->ndi_mm;
      o.corner_noise_px = a->corner_px;
      o.chain = a->chain;
      o.hand_eye_method = parse_hand_eye_method(a->method);
      o.seed = a->seed;
      o.render = a->render;
      o.render_noise_gray = a->render_noise;
      o.render_blur_px = a->render_blur;
      const ArSimResult res = simulate_ar_accuracy(o);
      trials = res.trials;
      stats = res.stats;
      const std::string camera_model = o.render
          ? "rendered images (synthetic camera, noise " + std::to_string(o.render_noise_gray) + " gray, blur " +
                std::to_string(o.render_blur_px) + " px) + AprilTag detector"
          : "projected corners + " + std::to_string(o.corner_noise_px) + " px Gaussian noise";
      r.line("  simulated bench: NDI sphere noise " + std::to_string(o.ndi_rms_mm) + " mm RMS; camera: " + camera_model +
             "; chain '" + o.chain + "', " + std::to_string(o.runs) + " calibration sessions x " +
             std::to_string(o.trials_per_angle) + " trials per angle");
      r.line("  simulated: marker-fit tool poses, camera corners as above, intrinsics/pivot/hand-eye from simulated");
      r.line("  data. NOT simulated: human alignment, rolling shutter, latency, NDI volumetric bias, tool geometry error.");
      r.kv("corner error vs truth", res.corner_error_rms_px, " px RMS per axis (", res.views_rendered, " rendered views)");
      double intr = 0, tip = 0, he = 0, cam_ndi = 0;
      for (const auto& run : res.runs) {
        intr += run.intrinsics_rms_px;
        tip += run.tip_error_mm;
        he += run.hand_eye_rms_mm;
        cam_ndi += run.X_CamNdi_error_mm;
      }
      const double n = static_cast<double>(res.runs.size());
      r.kv("mean intrinsics RMS", intr / n, " px");
      r.kv("mean pivot tip error", tip / n, " mm");
      r.kv("mean hand-eye residual RMS", he / n, " mm; mean X_CamNdi translation error ", cam_ndi / n, " mm");
      r.kv("wall time", res.wall_time_s, " s");
      j["simulation"] = {{"ndi_rms_mm", o.ndi_rms_mm}, {"corner_noise_px", o.corner_noise_px}, {"chain", o.chain},
                         {"runs", o.runs}, {"trials_per_angle", o.trials_per_angle}, {"seed", o.seed},
                         {"hand_eye", to_string(o.hand_eye_method)}, {"mean_tip_error_mm", tip / n},
                         {"mean_X_CamNdi_error_mm", cam_ndi / n}, {"wall_time_s", res.wall_time_s},
                         {"render", o.render}, {"corner_error_rms_px", res.corner_error_rms_px},
                         {"views_rendered", res.views_rendered}};
    } else {
      trials = read_ar_measurements(a->measurements);
      stats = summarize_ar_trials(trials);
      r.kv("measurements", a->measurements, " (", trials.size(), " trials)");
    }
    for (const auto& st : stats) {
      std::ostringstream line;
      line.precision(3);
      line << std::fixed << "  " << (std::isnan(st.view_angle_deg) ? std::string("all") : std::to_string(static_cast<int>(st.view_angle_deg)) + " deg")
           << ": " << st.mean_mm << " +- " << st.sd_mm << " mm (n " << st.n << ", min " << st.min_mm << ", max " << st.max_mm << ")";
      if (st.mean_image_px >= 0) line << ", image " << st.mean_image_px << " px, lateral " << st.mean_lateral_mm << " mm";
      r.line(line.str());
      nlohmann::json e = {{"n", st.n}, {"mean_mm", st.mean_mm}, {"sd_mm", st.sd_mm}, {"min_mm", st.min_mm}, {"max_mm", st.max_mm}};
      if (st.mean_image_px >= 0) {
        e["mean_image_px"] = st.mean_image_px;
        e["mean_lateral_mm"] = st.mean_lateral_mm;
      }
      if (std::isnan(st.view_angle_deg)) {
        j["all"] = e;
      } else {
        e["view_angle_deg"] = st.view_angle_deg;
        j["per_angle"].push_back(e);
      }
    }
    write_ar_trials_csv(dir / "ar_trials.csv", trials);
    write_ar_stats_csv(dir / "ar_stats.csv", stats);
    write_ar_chart(dir / "ar_accuracy.png", stats, a->simulate ? "Simulated AR error per view angle" : "AR error per view angle",
                   a->target_mm, "target " + std::to_string(a->target_mm).substr(0, 4) + " mm");
    r.file(dir / "ar_trials.csv", "every trial");
    r.file(dir / "ar_stats.csv", "mean +- sd per view angle");
    r.file(dir / "ar_accuracy.png", "plot");
    std::ofstream(dir / "ar_summary.json") << j.dump(2) << "\n";
    r.file(dir / "ar_summary.json", "summary (JSON)");
    r.save();
  };
}

}  // namespace arnav::calib::tool
