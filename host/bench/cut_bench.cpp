#include "host/bench/cut_bench.hpp"

#include <algorithm>
#include <cmath>
#include <chrono>
#include <ctime>
#include <fstream>
#include <iostream>
#include <stdexcept>

#include "host/bench/cut_reference.hpp"
#include "host/cut/cut_session.hpp"
#include "host/cut/material_path.hpp"
#include "host/cut/mesh_checks.hpp"
#include "host/cut/ring_path.hpp"
#include "host/cut/scalpel_path.hpp"
#include "host/scene/scene.hpp"
#include "host/sim/fem/corotational_fem.hpp"
#include "host/sim/model_factory.hpp"

namespace arnav::host {

namespace {

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t i = std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5));
  return v[i];
}

double thread_cpu_ms() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
}

// After a frame's blade (before the step: the tissue as the cutter cut it), the cut-path error
// in the material of the vertices the frame put on the cut; returns the time it took (ms).
double measure_path(cut::CutSession& session, bool cutting, const cut::CutFrameReport& cr, cut::MaterialPathMeter& meter,
                    std::vector<double>& path_error_mm) {
  const auto t0 = std::chrono::steady_clock::now();
  if (cutting && session.last_sweep()) meter.record_sweep(session.cutter(), session.positions_World_mm(), *session.last_sweep());
  if (cr.cut.topology_changed || cr.cut.vertices_snapped > 0) {
    double worst = -1.0;
    meter.measure_new_cut_vertices(session.cutter(), worst, &path_error_mm);
  }
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

bool selected(const std::string& label, const std::vector<std::string>& prefixes) {
  if (prefixes.empty()) return true;
  for (const auto& p : prefixes)
    if (label.rfind(p, 0) == 0) return true;
  return false;
}

}  // namespace

std::vector<CutBenchRow> run_cut_bench(const CutBenchOptions& o) {
  using namespace cut;
  std::vector<std::string> meshes = o.quick ? std::vector<std::string>{"coarse"} : o.meshes;
  std::vector<std::string> scenarios = o.quick ? std::vector<std::string>{"right_lobe"} : o.scenarios;
  std::vector<std::string> prefixes = o.quick ? std::vector<std::string>{"xpbd"} : o.setting_prefixes;
  std::vector<CutBenchRow> rows;
  CutReferences references(o);
  for (const auto& mesh_name : meshes) {
    if (mesh_name != "coarse" && mesh_name != "paper") throw std::invalid_argument("cut bench: unknown mesh '" + mesh_name + "' (coarse, paper)");
    const Scene scene = load_scene(o.data_dir + (mesh_name == "coarse" ? "/liver/liver_coarse_cut.scene.yaml" : "/liver/liver.scene.yaml"));
    const CutMeshCheck input = check_cut_mesh(scene.problem.mesh);
    for (const auto& scenario : scenarios) {
      if (scenario != "right_lobe" && scenario != "ring" && scenario != "ring_scene" && scenario != "ring_follow")
        throw std::invalid_argument("cut bench: unknown scenario '" + scenario + "' (right_lobe, ring, ring_scene, ring_follow)");
      // ring_scene: made from the scene after the organ settled (cut/ring_path.hpp), fixed in
      // World; ring_follow: the same path with the blade following the tumour's rigid motion
      // (follow_tracked: a surgeon keeping the ring round the lesion) until the bottom cut ends.
      const bool derived = scenario == "ring_scene" || scenario == "ring_follow";
      const bool follow = scenario == "ring_follow";
      const ScalpelPath csv_path = derived ? ScalpelPath{} : load_scalpel_csv(o.data_dir + "/liver/scalpel_" + scenario + ".csv");
      for (ModelVariant variant : model_variants())
      for (const bool background : o.background) {
      if (o.fem_background_refactor && !variant.config.refactor_in_background && variant.config.kind == "corotational_fem" &&
          variant.config.material_model != "stable_neo_hookean") {
        variant.config.refactor_in_background = true;
        variant.label += "+background_refactor";
      }
      const bool set_rings = o.fem_cut_region_rings >= -1 && variant.config.kind == "corotational_fem" &&
                             variant.config.material_model != "stable_neo_hookean";
      if (set_rings) variant.label += "+cut_rings" + std::to_string(o.fem_cut_region_rings);
      std::vector<Eigen::Matrix3Xd> rebuilt_states;  // per frame, of the rebuilt run (local_updates both)
      std::vector<bool> local_modes = o.local_updates;
      std::stable_sort(local_modes.begin(), local_modes.end());  // rebuilt run first
      for (const bool local_updates : local_modes) {
        if (!selected(variant.label, prefixes)) continue;
        // The scene's cutting section (docs/cut.md defaults without one).
        CutSessionSettings settings = scene.cutting ? cut_settings_from(*scene.cutting) : CutSessionSettings{};
        settings.rebuild_in_background = background;
        settings.local_updates = local_updates;
        // The ring made from the scene (about 21 mm in radius): sides within 20 mm while the
        // blade passes (CutSettings::side_distance_mm, docs/cut.md).
        if (derived) settings.cut.side_distance_mm = 20.0;
        if (o.min_dihedral_deg >= 0) settings.min_dihedral_deg = o.min_dihedral_deg;
        if (o.chord_sagitta_mm >= 0) settings.cut.chord_sagitta_mm = o.chord_sagitta_mm;
        const std::unique_ptr<CutSession> session_ptr = make_cut_session(scene, variant.config, settings);
        CutSession& session = *session_ptr;
        if (set_rings)
          if (auto* fem = dynamic_cast<CorotationalFem*>(&session.model())) fem->set_cut_region_rings(o.fem_cut_region_rings);
        CutBenchRow row;
        row.mesh = mesh_name;
        row.scenario = scenario;
        row.label = variant.label;
        row.background = background;
        row.local_updates_enabled = local_updates;
        const bool record = !local_updates && local_modes.back();
        const bool compare = local_updates && !rebuilt_states.empty();
        bool parted = false;
        row.tets_before = scene.problem.mesh.num_tets();
        row.chord_sagitta_mm = settings.cut.chord_sagitta_mm;
        row.min_dihedral_input_deg = input.min_dihedral_deg;
        std::vector<double> topology, frame, rebuild, local, frame_cpu, path_error;
        cut::MaterialPathMeter meter(1 << 20);  // the cut-path error in the material, every sweep of the run
        ScalpelPath path = csv_path;
        int first = 1;  // frames before it: the organ settling under gravity (derived ring)
        RingPath ring;
        Eigen::Matrix3Xd tumour_then, tumour_tracked;  // ring_follow: the tumour when the path was made, and as last tracked
        bool tracking = follow;
        if (derived) {
          // The organ hangs 2 s with the blade away, then the ring is made round the tumour as
          // it hangs (the access direction that keeps the ligaments out of the block).
          const int settle = static_cast<int>(std::lround(2.0 / scene.time_step_s));
          const Eigen::Vector3d far = session.positions_World_mm().rowwise().mean() + Eigen::Vector3d(0, 0, 1e4);
          for (int f = 1; f <= settle && row.healthy; ++f) {
            session.apply_blade({far, far + Eigen::Vector3d(0, 0, 1)}, false);
            const StepSummary step = session.step(scene.time_step_s);
            if (!step.healthy) {
              row.healthy = false;
              row.warning = "before the cut: " + step.warning;
            }
          }
          const Eigen::Matrix3Xd x = session.positions_World_mm();
          tumour_then = session.tumours().front().embedding.apply(session.mesh(), x);
          tumour_tracked = tumour_then;
          ring = make_ring_path(session.mesh(), x, session.fixed_vertices(), tumour_then);
          for (auto& sample : ring.path.samples) sample.t_s += settle * scene.time_step_s;
          ring.ring_end_s += settle * scene.time_step_s;
          ring.cut_end_s += settle * scene.time_step_s;
          path = ring.path;
          first = settle + 1;
          row.ring_radius_mm = ring.radius_mm;
          row.ring_axis = ring.axis;
        }
        int frames = static_cast<int>(path.samples.back().t_s / scene.time_step_s) + 1;
        if (o.quick) frames = std::min(frames, 150);
        if (o.max_frames > 0) frames = std::min(frames, o.max_frames);
        Eigen::Vector3d tumour_at_cut_end = Eigen::Vector3d::Zero();
        Eigen::Matrix3Xd x_at_cut_end;
        for (int f = first; f <= frames && row.healthy; ++f) {
          ScalpelSample s = path.at(f * scene.time_step_s);
          if (follow) {
            if (tracking && f * scene.time_step_s < ring.cut_end_s)
              tumour_tracked = session.tumours().front().embedding.apply(session.mesh(), session.positions_World_mm()).leftCols(tumour_then.cols());
            s.blade = follow_tracked(s.blade, tumour_then, tumour_tracked);
          }
          const auto t0 = std::chrono::steady_clock::now();
          const double cpu0 = thread_cpu_ms();
          const CutFrameReport cr = session.apply_blade(s.blade, s.cutting);
          const double meter_ms = measure_path(session, s.cutting, cr, meter, path_error);  // not the frame's time
          const StepSummary step = session.step(scene.time_step_s);
          frame.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count() - meter_ms);
          frame_cpu.push_back(thread_cpu_ms() - cpu0 - meter_ms);
          // ring_follow: once the block is free the surgeon stops following it (outside the
          // frame's timing: an O(tets) check of the tumour's piece after topology changes).
          if (tracking && cr.cut.topology_changed && piece_is_free(session.mesh(), session.tumours().front().embedding.tet.front(), session.fixed_vertices()))
            tracking = false;
          if (record) rebuilt_states.push_back(session.positions_World_mm());
          if (compare && !parted && static_cast<std::size_t>(f - first) < rebuilt_states.size()) {
            const Eigen::Matrix3Xd x = session.positions_World_mm();
            const Eigen::Matrix3Xd& y = rebuilt_states[static_cast<std::size_t>(f - first)];
            parted = x.cols() != y.cols();  // the cuts differ from here on: not comparable
            if (!parted) {
              const double d = (x - y).colwise().norm().maxCoeff();
              row.state_diff_max_mm = std::max(row.state_diff_max_mm, d);
              row.state_diff_final_mm = d;
              ++row.state_compared_frames;
            }
          }
          topology.push_back(cr.cut.update_ms);
          row.frame_timings.push_back({f, frame.back(), frame_cpu.back(), cr.cut.update_ms, cr.cut.topology_changed ? cr.rebuild_ms : 0.0,
                                       cr.reembed_ms, step.wall_time_ms, static_cast<int>(cr.cut.changed_tets.size()),
                                       cr.cut.topology_changed, step.iterations, step.final_residual});
          row.frames = f;
          row.events += static_cast<int>(cr.events.size());
          row.path_fidelity_mm = std::max(row.path_fidelity_mm, cr.cut.max_path_deviation_mm);
          row.completion_deviation_mm = std::max(row.completion_deviation_mm, cr.cut.max_completion_deviation_mm);
          row.completed_tets += cr.cut.tets_completed;
          if (cr.cut.topology_changed) {
            ++row.topology_changes;
            (cr.local_update ? local : rebuild).push_back(cr.rebuild_ms);
          }
          if (!step.healthy) {
            row.healthy = false;
            row.warning = step.warning;
            break;
          }
          if (derived && x_at_cut_end.cols() == 0 && f * scene.time_step_s >= ring.cut_end_s) {
            x_at_cut_end = session.positions_World_mm();
            tumour_at_cut_end = session.tumours().front().embedding.apply(session.mesh(), x_at_cut_end).rowwise().mean();
          }
        }
        const CutMeshCheck after = check_cut_mesh(session.mesh());
        row.tets_after = session.mesh().num_tets();
        row.vertices_after = session.mesh().num_vertices();
        row.new_tets = row.tets_after - row.tets_before;
        row.path_error_p50_mm = percentile(path_error, 0.5);
        row.path_error_p95_mm = percentile(path_error, 0.95);
        row.path_error_max_mm = percentile(path_error, 1.0);
        row.cut_vertices_measured = static_cast<int>(path_error.size());
        row.topology_median_ms = percentile(topology, 0.5);
        row.topology_p99_ms = percentile(topology, 0.99);
        row.topology_max_ms = percentile(topology, 1.0);
        row.frame_median_ms = percentile(frame, 0.5);
        row.frame_p99_ms = percentile(frame, 0.99);
        row.frame_thread_cpu_median_ms = percentile(frame_cpu, 0.5);
        row.frame_thread_cpu_p99_ms = percentile(frame_cpu, 0.99);
        row.rebuild_median_ms = percentile(rebuild, 0.5);
        row.rebuild_p99_ms = percentile(rebuild, 0.99);
        row.min_dihedral_deg = after.min_dihedral_deg;
        {  // the quality bound: elastic (active) tets and the embedded ones
          const EmbeddedElements& emb = session.embedded();
          const TetMesh& m = session.mesh();
          row.min_dihedral_bound_deg = settings.min_dihedral_deg;
          row.min_dihedral_active_deg = 180.0;
          double embedded_volume = 0.0, volume = 0.0;
          for (int t = 0; t < m.num_tets(); ++t) {
            const auto& tet = m.tets[static_cast<std::size_t>(t)];
            const Eigen::Matrix3Xd& X = m.rest_positions_World_mm;
            const double V = (X.col(tet[1]) - X.col(tet[0])).dot((X.col(tet[2]) - X.col(tet[0])).cross(X.col(tet[3]) - X.col(tet[0]))) / 6.0;
            volume += V;
            if (emb.is_passive(t)) {
              ++row.embedded_tets;
              embedded_volume += V;
            } else {
              row.min_dihedral_active_deg = std::min(row.min_dihedral_active_deg, tet_min_dihedral_deg(X, tet));
            }
          }
          row.embedded_volume_fraction = volume > 0 ? embedded_volume / volume : 0.0;
          row.driven_vertices = static_cast<int>(emb.driven.size());
          row.rigid_groups = static_cast<int>(emb.rigid_groups.size());
        }
        row.volume_change_rel = after.total_volume_mm3 / input.total_volume_mm3 - 1.0;
        row.mesh_valid = after.valid();
        row.pieces = static_cast<int>(after.piece_volume_mm3.size());
        std::vector<char> fixed_piece(after.piece_volume_mm3.size(), 0);
        std::vector<char> is_fixed(static_cast<std::size_t>(session.mesh().num_vertices()), 0);
        for (int v : session.fixed_vertices()) is_fixed[static_cast<std::size_t>(v)] = 1;
        for (int t = 0; t < session.mesh().num_tets(); ++t)
          for (int v : session.mesh().tets[static_cast<std::size_t>(t)])
            if (is_fixed[static_cast<std::size_t>(v)]) fixed_piece[static_cast<std::size_t>(after.piece_of_tet[static_cast<std::size_t>(t)])] = 1;
        row.free_pieces = static_cast<int>(std::count(fixed_piece.begin(), fixed_piece.end(), 0));
        for (const auto& tumour : session.tumours()) {
          std::vector<int> pieces;
          for (int t : tumour.embedding.tet) pieces.push_back(after.piece_of_tet[static_cast<std::size_t>(t)]);
          std::sort(pieces.begin(), pieces.end());
          pieces.erase(std::unique(pieces.begin(), pieces.end()), pieces.end());
          if (pieces.size() == 1 && !fixed_piece[static_cast<std::size_t>(pieces[0])]) ++row.tumours_freed;
          const auto largest = std::max_element(after.piece_volume_mm3.begin(), after.piece_volume_mm3.end()) - after.piece_volume_mm3.begin();
          if (pieces.size() == 1 && pieces[0] != static_cast<int>(largest)) ++row.tumours_separated;
        }
        if (derived && x_at_cut_end.cols() > 0 && row.healthy) {
          const Eigen::Matrix3Xd x = session.positions_World_mm();
          row.freed_drop_mm = (session.tumours().front().embedding.apply(session.mesh(), x).rowwise().mean() - tumour_at_cut_end).norm();
          const auto largest = std::max_element(after.piece_volume_mm3.begin(), after.piece_volume_mm3.end()) - after.piece_volume_mm3.begin();
          row.organ_drift_mm = 0.0;
          for (int t = 0; t < session.mesh().num_tets(); ++t)
            if (after.piece_of_tet[static_cast<std::size_t>(t)] == static_cast<int>(largest))
              for (int v : session.mesh().tets[static_cast<std::size_t>(t)])
                if (v < x_at_cut_end.cols()) row.organ_drift_mm = std::max(row.organ_drift_mm, (x.col(v) - x_at_cut_end.col(v)).norm());
        }
        row.local_updates = session.local_updates();
        row.rebuilds = session.rebuilds();
        row.local_median_ms = percentile(local, 0.5);
        row.local_p99_ms = percentile(local, 0.99);
        if (!o.reference_mesh.empty() && !derived) add_reference_errors(references, scenario, variant, settings, session, row);
        std::cerr << "arnav-bench cut: " << mesh_name << " " << scenario << " " << variant.label << (background ? " (background rebuild)" : "") << ": " << row.frames << " frames, frame "
                  << row.frame_median_ms << "/" << row.frame_p99_ms << " ms (median/p99; stepping thread CPU " << row.frame_thread_cpu_median_ms << "/"
                  << row.frame_thread_cpu_p99_ms << " ms), topology " << row.topology_median_ms << "/"
                  << row.topology_p99_ms << " ms, local update " << row.local_median_ms << "/" << row.local_p99_ms << " ms (" << row.local_updates
                  << "), rebuild " << row.rebuild_median_ms << " ms (" << row.rebuilds << "), pieces " << row.pieces << ", tumours freed " << row.tumours_freed << ", separated " << row.tumours_separated << (derived ? ", freed block dropped " + std::to_string(row.freed_drop_mm) + " mm, organ drift " + std::to_string(row.organ_drift_mm) + " mm" : std::string()) << ", min dihedral " << row.min_dihedral_deg
                  << " (active " << row.min_dihedral_active_deg << ", embedded " << row.embedded_tets << " tets, " << row.driven_vertices << " driven, " << row.rigid_groups << " rigid)"
                  << (row.healthy ? "" : " UNHEALTHY: " + row.warning) << "\n";
        if (compare)
          std::cerr << "arnav-bench cut:   against the rebuilt run: state difference " << row.state_diff_max_mm << " mm at most, "
                    << row.state_diff_final_mm << " mm at the end (" << row.state_compared_frames << " frames compared)\n";
        rows.push_back(row);
      }
      }
    }
  }
  return rows;
}

void write_cut_csv(const std::string& path, const std::vector<CutBenchRow>& rows) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error("cannot write " + path + ": check the folder");
  out << "mesh,scenario,model,background_rebuild,tets_before,tets_after,vertices_after,frames,topology_changes,new_tets,topology_median_ms,topology_p99_ms,"
         "topology_max_ms,frame_median_ms,frame_p99_ms,rebuild_median_ms,rebuild_p99_ms,min_dihedral_input_deg,min_dihedral_deg,"
         "min_dihedral_bound_deg,min_dihedral_active_deg,embedded_tets,embedded_volume_fraction,driven_vertices,rigid_groups,"
         "volume_change_rel,path_fidelity_mm,completion_deviation_mm,completed_tets,pieces,free_pieces,tumours_freed,tumours_separated,freed_drop_mm,organ_drift_mm,ring_radius_mm,local_updates,local_median_ms,local_p99_ms,rebuilds,events,mesh_valid,healthy,warning,"
         "local_updates_enabled,state_diff_max_mm,state_diff_final_mm,state_compared_frames,frame_thread_cpu_median_ms,frame_thread_cpu_p99_ms,"
         "path_error_p50_mm,path_error_p95_mm,path_error_max_mm,cut_vertices_measured,chord_sagitta_mm\n";
  for (const auto& r : rows) {
    std::string warning = r.warning;
    std::replace(warning.begin(), warning.end(), ',', ';');
    out << r.mesh << ',' << r.scenario << ',' << r.label << ',' << (r.background ? 1 : 0) << ',' << r.tets_before << ',' << r.tets_after << ',' << r.vertices_after << ','
        << r.frames << ',' << r.topology_changes << ',' << r.new_tets << ',' << r.topology_median_ms << ',' << r.topology_p99_ms << ','
        << r.topology_max_ms << ',' << r.frame_median_ms << ',' << r.frame_p99_ms << ',' << r.rebuild_median_ms << ',' << r.rebuild_p99_ms
        << ',' << r.min_dihedral_input_deg << ',' << r.min_dihedral_deg << ',' << r.min_dihedral_bound_deg << ',' << r.min_dihedral_active_deg
        << ',' << r.embedded_tets << ',' << r.embedded_volume_fraction << ',' << r.driven_vertices << ',' << r.rigid_groups
        << ',' << r.volume_change_rel << ',' << r.path_fidelity_mm << ','
        << r.completion_deviation_mm << ',' << r.completed_tets << ',' << r.pieces << ',' << r.free_pieces << ',' << r.tumours_freed << ',' << r.tumours_separated << ',' << r.freed_drop_mm << ',' << r.organ_drift_mm << ',' << r.ring_radius_mm << ',' << r.local_updates << ',' << r.local_median_ms << ',' << r.local_p99_ms << ',' << r.rebuilds << ',' << r.events << ',' << (r.mesh_valid ? 1 : 0) << ','
        << (r.healthy ? 1 : 0) << ',' << warning << ',' << (r.local_updates_enabled ? 1 : 0) << ',' << r.state_diff_max_mm << ','
        << r.state_diff_final_mm << ',' << r.state_compared_frames << ',' << r.frame_thread_cpu_median_ms << ',' << r.frame_thread_cpu_p99_ms << ','
        << r.path_error_p50_mm << ',' << r.path_error_p95_mm << ',' << r.path_error_max_mm << ',' << r.cut_vertices_measured << ',' << r.chord_sagitta_mm << '\n';
  }
}

void write_cut_frames_csv(const std::string& path, const std::vector<CutBenchRow>& rows) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error("cannot write " + path + ": check the folder");
  out << "mesh,scenario,model,local_updates_enabled,background_rebuild,frame,frame_ms,frame_thread_cpu_ms,topology_ms,model_update_ms,reembed_ms,step_ms,"
         "changed_tets,topology_changed,iterations,final_residual\n";
  for (const auto& r : rows)
    for (const auto& f : r.frame_timings)
      out << r.mesh << ',' << r.scenario << ',' << r.label << ',' << (r.local_updates_enabled ? 1 : 0) << ',' << (r.background ? 1 : 0) << ','
          << f.frame << ',' << f.frame_ms << ',' << f.frame_cpu_ms << ',' << f.topology_ms << ',' << f.model_update_ms << ',' << f.reembed_ms
          << ',' << f.step_ms << ',' << f.changed_tets << ',' << (f.topology_changed ? 1 : 0) << ',' << f.iterations << ',' << f.final_residual << '\n';
}

}  // namespace arnav::host
