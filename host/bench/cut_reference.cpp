#include "host/bench/cut_reference.hpp"

#include <algorithm>
#include <chrono>
#include <fstream>
#include <iostream>
#include <stdexcept>

#include "host/bench/pareto_plot.hpp"
#include "host/cut/bvh.hpp"
#include "host/cut/scalpel_path.hpp"
#include "host/scene/scene.hpp"
#include "host/mesh/surface_shapes.hpp"

namespace arnav::host {

namespace {

std::string scene_of(const std::string& data_dir, const std::string& mesh) {
  if (mesh == "coarse") return data_dir + "/liver/liver_coarse_cut.scene.yaml";
  if (mesh == "paper") return data_dir + "/liver/liver.scene.yaml";
  throw std::invalid_argument("cut bench: unknown reference mesh '" + mesh + "' (coarse, paper)");
}

Eigen::Vector3d closest_on_triangle(const Eigen::Vector3d& p, const cut::Triangle& t) {
  // Ericson, Real-Time Collision Detection 5.1.5 (Voronoi regions of the triangle).
  const Eigen::Vector3d ab = t.b - t.a, ac = t.c - t.a, ap = p - t.a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return t.a;
  const Eigen::Vector3d bp = p - t.b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return t.b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return t.a + d1 / (d1 - d3) * ab;
  const Eigen::Vector3d cp = p - t.c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return t.c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return t.a + d2 / (d2 - d6) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return t.b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (t.c - t.b);
  const double denom = 1.0 / (va + vb + vc);
  return t.a + ab * (vb * denom) + ac * (vc * denom);
}

// Distance of every triangle's sample points (centroid, corners) of `from` to the set `to`
// (a hierarchy over `to`, searched with a growing box): area-weighted sum and largest.
void one_way(const std::vector<cut::Triangle>& from, const std::vector<cut::Triangle>& to, const cut::Bvh& bvh, double& weighted,
             double& area, double& largest) {
  for (const auto& t : from) {
    const double a = 0.5 * (t.b - t.a).cross(t.c - t.a).norm();
    double tri_sum = 0;
    for (const Eigen::Vector3d& p : {Eigen::Vector3d((t.a + t.b + t.c) / 3.0), t.a, t.b, t.c}) {
      double best = 1e300;
      for (double r = 1.0; best > 1e299; r *= 4.0) {
        cut::Aabb box;
        box.extend(p);
        bvh.query(box.inflated(r), [&](int i) { best = std::min(best, (closest_on_triangle(p, to[static_cast<std::size_t>(i)]) - p).norm()); });
        if (best > r) best = 1e300;  // something nearer may lie outside the box: grow it
        if (r > 1e6) break;
      }
      tri_sum += best;
      largest = std::max(largest, best);
    }
    weighted += a * tri_sum / 4.0;
    area += a;
  }
}

}  // namespace

CutOutcome cut_outcome(cut::CutSession& session) {
  CutOutcome out;
  const Eigen::Matrix3Xd x = session.positions_World_mm();
  if (!session.tumours().empty()) {
    out.has_tumour = true;
    out.tumour_centroid_World_mm = closed_surface_centroid(session.tumours()[0].embedding.apply(session.mesh(), x), session.tumour_tris()[0]);
  }
  const auto& c = session.cutter();
  for (const auto& f : session.surface_tris())
    if (c.on_cut(f[0]) && c.on_cut(f[1]) && c.on_cut(f[2])) out.cut_faces.push_back({x.col(f[0]), x.col(f[1]), x.col(f[2])});
  out.tets = session.mesh().num_tets();
  return out;
}

SurfaceDistance surface_distance(const std::vector<cut::Triangle>& a, const std::vector<cut::Triangle>& b) {
  SurfaceDistance d;
  if (a.empty() || b.empty()) return d;
  const auto boxes = [](const std::vector<cut::Triangle>& tris) {
    std::vector<cut::Aabb> out;
    for (const auto& t : tris) {
      cut::Aabb box;
      box.extend(t.a);
      box.extend(t.b);
      box.extend(t.c);
      out.push_back(box);
    }
    return out;
  };
  cut::Bvh bvh_a, bvh_b;
  bvh_a.build(boxes(a));
  bvh_b.build(boxes(b));
  double weighted = 0, area = 0;
  one_way(a, b, bvh_b, weighted, area, d.max_mm);
  one_way(b, a, bvh_a, weighted, area, d.max_mm);
  d.mean_mm = area > 0 ? weighted / area : 0.0;
  d.valid = true;
  return d;
}

const CutOutcome& CutReferences::get(const std::string& scenario, const ModelVariant& variant, int frames, const cut::CutSessionSettings& settings) {
  const auto key = std::make_tuple(scenario, variant.label, frames);
  if (const auto it = done_.find(key); it != done_.end()) return it->second;
  const auto t0 = std::chrono::steady_clock::now();
  const Scene scene = load_scene(scene_of(options_.data_dir, options_.reference_mesh));
  const cut::ScalpelPath path = cut::load_scalpel_csv(options_.data_dir + "/liver/scalpel_" + scenario + ".csv");
  cut::CutSessionSettings s = settings;
  s.rebuild_in_background = false;  // the reference: deterministic, the model takes every cut at once
  const std::unique_ptr<cut::CutSession> session = cut::make_cut_session(scene, variant.config, s);
  CutOutcome out;
  bool healthy = true;
  std::string warning;
  int f = 1;
  for (; f <= frames; ++f) {
    const cut::ScalpelSample sample = path.at(f * scene.time_step_s);
    session->apply_blade(sample.blade, sample.cutting);
    const StepSummary step = session->step(scene.time_step_s);
    if (!step.healthy) {
      healthy = false;
      warning = step.warning;
      break;
    }
  }
  out = cut_outcome(*session);
  out.healthy = healthy;
  out.warning = warning;
  out.frames = std::min(f, frames);
  out.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::cerr << "arnav-bench cut: reference " << options_.reference_mesh << " " << scenario << " " << variant.label << ": " << out.frames << " frames, "
            << out.tets << " tets, " << out.cut_faces.size() << " cut faces, " << out.wall_s << " s" << (healthy ? "" : " UNHEALTHY: " + warning) << "\n";
  return done_.emplace(key, std::move(out)).first->second;
}

void add_reference_errors(CutReferences& references, const std::string& scenario, const ModelVariant& variant, const cut::CutSessionSettings& settings,
                          cut::CutSession& session, CutBenchRow& row) {
  const CutOutcome& ref = references.get(scenario, variant, row.frames, settings);
  const CutOutcome run = cut_outcome(session);
  row.reference_mesh = references.mesh();
  row.reference_tets = ref.tets;
  row.reference_healthy = ref.healthy;
  row.reference_wall_s = ref.wall_s;
  if (run.has_tumour && ref.has_tumour) row.tumour_centroid_error_mm = (run.tumour_centroid_World_mm - ref.tumour_centroid_World_mm).norm();
  const SurfaceDistance d = surface_distance(run.cut_faces, ref.cut_faces);
  if (d.valid) {
    row.cut_surface_mean_mm = d.mean_mm;
    row.cut_surface_max_mm = d.max_mm;
  }
}

void write_cut_reference_csv(const std::string& path, const std::vector<CutBenchRow>& rows) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error("cannot write " + path + ": check the folder");
  out << "mesh,scenario,model,background_rebuild,tets_after,frames,frame_median_ms,frame_p99_ms,healthy,reference_mesh,reference_tets,reference_healthy,"
         "reference_wall_s,tumour_centroid_error_mm,cut_surface_mean_mm,cut_surface_max_mm\n";
  for (const auto& r : rows)
    out << r.mesh << ',' << r.scenario << ',' << r.label << ',' << (r.background ? 1 : 0) << ',' << r.tets_after << ',' << r.frames << ','
        << r.frame_median_ms << ',' << r.frame_p99_ms << ',' << (r.healthy ? 1 : 0) << ',' << r.reference_mesh << ',' << r.reference_tets << ','
        << (r.reference_healthy ? 1 : 0) << ',' << r.reference_wall_s << ',' << r.tumour_centroid_error_mm << ',' << r.cut_surface_mean_mm << ','
        << r.cut_surface_max_mm << '\n';
}

void write_cut_reference_png(const std::string& path, const std::vector<CutBenchRow>& rows) {
  // The deform benchmark's error-against-time plot (pareto_plot.hpp): one panel per
  // scenario and error; x is the run's median wall time per frame.
  DeformBenchResult plot;
  for (const auto& r : rows) {
    ModelConfig config;
    for (const auto& v : model_variants())
      if (v.label == r.label) config = v.config;
    for (int e = 0; e < 2; ++e) {
      const double err = e == 0 ? r.tumour_centroid_error_mm : r.cut_surface_mean_mm;
      if (err < 0) continue;
      DeformBenchRow p;
      p.scenario = "cut " + r.scenario + (e == 0 ? ": tumour centroid" : ": cut surface (mean)");
      p.label = r.label;
      p.mesh = r.mesh == r.reference_mesh ? "fine" : "coarse";
      p.config = config;
      p.median_frame_cpu_ms = r.frame_median_ms;
      p.tumour_error_mm = std::max(err, 1e-3);
      p.reference_tets = r.reference_tets;
      p.healthy = r.healthy && r.reference_healthy;
      plot.rows.push_back(p);
    }
  }
  if (plot.rows.empty()) throw std::runtime_error("cut bench: no reference errors to plot (no run had a tumour or cut faces)");
  int ref_tets = 0;
  for (const auto& r : rows) ref_tets = std::max(ref_tets, r.reference_tets);
  write_pareto_png(path, plot,
                   {"median wall time per 1/60 s frame of the cut run (ms)", "error against the reference cut (mm)",
                    "x: unhealthy run; reference: same path, same model, " + std::to_string(ref_tets) + " tets"});
}

}  // namespace arnav::host
