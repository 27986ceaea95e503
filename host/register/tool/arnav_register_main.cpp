// arnav-register: registers the patient model of a scene to an intraoperative surface
// (rigid: landmarks + point-to-plane ICP; non-rigid: the scene's tissue model pulled by
// the data through attachments), carries targets through it and writes the results.
//   arnav-register SCENE --surface FILE [--landmarks FILE] [--initial-pose FILE]
//                  [--targets FILE] [--rigid-only] --out DIR
// Frames: Model (the scene frame) and Intraop (the frame of the surface and landmarks).
// Exit codes: 0 done, 1 not converged (files written, reason printed), 2 bad input.
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <lcm/lcm-cpp.hpp>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <optional>
#include <fstream>
#include <iostream>
#include <sstream>

#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/plot.hpp"
#include "calibration/lib/rigid_transform_file.hpp"
#include "host/register/basis_cache.hpp"
#include "host/register/cloud_collector.hpp"
#include "host/register/point_cloud.hpp"
#include "host/register/point_files.hpp"
#include "host/register/registration.hpp"
#include "host/mesh/load_error.hpp"
#include "host/mesh/mesh_io.hpp"
#include "host/scene/scene.hpp"
#include "protocol/guarded_main.hpp"
#include "protocol/seal/sealed_lcm.hpp"

namespace {

using namespace arnav::host;
using nlohmann::json;

struct Inputs {
  std::string scene_path, surface_path, landmarks_path, pose_path, targets_path, out_dir;
  std::string lcm_url, cloud_channel = "ARNAV_CLOUD_pointer", cloud_frame;
  std::string key_file, security;  // with --lcm: the bus key, or "off" (docs/protocol.md, "Sealed bus")
  double swab_seconds = 30.0, swab_wait_seconds = 60.0;
  bool rigid_only = false;
};

json icp_json(const IcpSummary& s) {
  json h = json::array();
  for (const auto& it : s.history) h.push_back({{"rms_mm", it.rms_mm}, {"points_used", it.used}, {"step_mm", it.step_mm}});
  return {{"iterations", s.iterations},       {"initial_point_to_plane_rms_mm", s.initial_rms_mm},
          {"residual_rms_mm", s.final_rms_mm}, {"residual_max_mm", s.final_max_mm},
          {"points_used", s.points_used},      {"points_trimmed", s.points_trimmed},
          {"wall_time_s", s.wall_time_s},      {"termination", s.termination},
          {"history", h}};
}

json matrix_json(const Eigen::Isometry3d& X) {
  json m = json::array();
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) m.push_back(X.matrix()(r, c));
  return m;
}

// Collects a live swab: arnav.point_cloud_t messages on the channel, from the first
// message for swab_seconds (or until a replayed log ends). Throws LoadError naming the
// URL and channel when nothing usable arrives.
PointCloud collect_swab(const Inputs& in) {
  arnav::seal::BusSecurity security;
  try {
    security = arnav::seal::security_from_cli(in.key_file, in.security, "arnav-register --lcm");
  } catch (const arnav::seal::SecurityError& e) {
    throw LoadError(e.what());
  }
  std::cerr << "arnav-register: " << security.describe() << "\n";
  arnav::seal::SealedLcm lcm(in.lcm_url, security);
  if (!lcm.good())
    throw LoadError("--lcm '" + in.lcm_url + "': cannot open LCM there. Fix: check the URL (udpm://GROUP:PORT?ttl=0, file://LOG?speed=0)");
  PointCloudCollector collector(in.cloud_frame);
  std::string error;
  struct Handler {
    PointCloudCollector* c;
    std::string* error;
    void on(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
      try {
        c->add_message(rbuf->data, rbuf->data_size, channel);
      } catch (const LoadError& e) {
        if (error->empty()) *error = e.what();  // the first bad message is reported; the rest still count
      }
    }
  } handler{&collector, &error};
  lcm.subscribe(in.cloud_channel, &Handler::on, &handler);
  std::cerr << "arnav-register: collecting the swab on " << in.cloud_channel << " from " << in.lcm_url << " (" << in.swab_seconds
            << " s after the first message)\n";
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  std::optional<Clock::time_point> first;
  while (true) {
    const auto now = Clock::now();
    if (!first && collector.messages() + collector.wrong_frame() + collector.duplicates() > 0) first = now;
    if (first && now - *first > std::chrono::duration<double>(in.swab_seconds)) break;
    if (!first && now - start > std::chrono::duration<double>(in.swab_wait_seconds)) break;
    const int rc = lcm.handleTimeout(100);
    if (rc < 0) break;  // a replayed log ended (or the provider failed)
  }
  if (!error.empty()) std::cerr << "arnav-register: refused a message: " << error << "\n";
  std::cerr << "arnav-register: swab: " << collector.summary() << "\n";
  if (collector.messages() == 0)
    throw LoadError("--lcm '" + in.lcm_url + "': no usable arnav.point_cloud_t on " + in.cloud_channel +
                    (collector.wrong_frame() > 0 ? " (" + collector.summary() + ")" : " within " + std::to_string(in.swab_wait_seconds) + " s") +
                    ". Fix: is the appliance publishing the pointer swab (swab: section of its configuration, docs/register.md), on this channel and URL?" +
                    (error.empty() ? "" : " First refused message: " + error));
  return collector.cloud();
}

}  // namespace

static int main_body(int argc, char** argv) {
  CLI::App app{"arnav-register: register a scene's patient model to an intraoperative surface (docs/register.md)"};
  Inputs in;
  RegistrationRequest rq;
  double noise_mm = rq.nonrigid.noise_mm;
  bool scene_boundary = false;
  app.add_option("scene", in.scene_path, "scene file, e.g. data/liver/liver_coarse.scene.yaml")->required();
  auto* surface_opt = app.add_option("--surface", in.surface_path, "intraoperative points: .xyz/.txt/.csv, .ply, .obj or .vtk (mm, Intraop frame)");
  auto* lcm_opt = app.add_option("--lcm", in.lcm_url, "register from a live swab: collect arnav.point_cloud_t messages from this LCM URL (e.g. udpm://239.255.76.67:7667?ttl=0, or file://LOG?speed=0 to replay a log)");
  surface_opt->excludes(lcm_opt);
  app.add_option("--key", in.key_file, "with --lcm: the bus key (arnav-keygen; docs/protocol.md)");
  app.add_option("--security", in.security, "with --lcm: 'off' for a bus or log that is not sealed");
  app.add_option("--cloud-channel", in.cloud_channel, "with --lcm: the point_cloud_t channel (default ARNAV_CLOUD_pointer)");
  app.add_option("--cloud-frame", in.cloud_frame, "with --lcm: the frame the points must be in (default: the first message's)");
  app.add_option("--swab-seconds", in.swab_seconds, "with --lcm: collect this long after the first message (default 30)")->check(CLI::Range(0.1, 3600.0));
  app.add_option("--swab-wait-seconds", in.swab_wait_seconds, "with --lcm: give up when no message came within this time (default 60)")->check(CLI::Range(0.1, 3600.0));
  app.add_option("--landmarks", in.landmarks_path, "CSV name,model_x,model_y,model_z,intraop_x,intraop_y,intraop_z (mm)");
  app.add_option("--initial-pose", in.pose_path,
                 "X_IntraopModel.yaml to start the surface registration from, or 'identity' for data already in the scene's frame "
                 "(aligned); the start carries the uncertainty --pose-sigma-deg / --pose-sigma-mm");
  bool no_pose_prior = false;
  app.add_flag("--no-pose-prior", no_pose_prior,
               "do not use the start's uncertainty as a prior (before issue 22: the surface fits may then slide along a partial patch)");
  app.add_option("--pose-sigma-deg", rq.prior.rotation_deg, "uncertainty (1 sigma, deg, about each axis) of a given pose or the identity (default 3)")
      ->check(CLI::Range(0.01, 180.0));
  app.add_option("--pose-sigma-mm", rq.prior.translation_mm, "uncertainty (1 sigma, mm, along each axis at the organ's centre) of a given pose or the identity (default 5)")
      ->check(CLI::Range(0.01, 1000.0));
  app.add_option("--hold-supports-mm", rq.prior.support_sigma_mm,
                 "with a given pose and fixed vertices in the scene: the supports' motion prior (1 sigma, mm; default 2; 0: not held)")
      ->check(CLI::Range(0.0, 100.0));
  app.add_option("--targets", in.targets_path, "CSV name,x_mm,y_mm,z_mm in the scene (Model) frame");
  app.add_flag("--rigid-only", in.rigid_only, "stop after the rigid registration");
  app.add_option("-o,--out", in.out_dir, "output folder")->required();
  app.add_option("--method", rq.nonrigid_method,
                 "non-rigid method: loads (default: unseen loads estimated with the pose from a linear elastic load basis) or energy "
                 "(paper 002: the tissue model pulled by the data, stiff to flexible)")
      ->check(CLI::IsMember({"loads", "energy"}));
  std::string basis_cache;
  app.add_option("--basis-cache", basis_cache,
                 "loads: keep the load basis in this folder (made if missing): a later run with the same volume, materials, fixed vertices "
                 "and basis options loads it instead of building it; a damaged or stale file is rebuilt with a warning (default: off)");
  app.add_option("--patches", rq.basis.patches, "loads: surface patches of the load basis (3 force modes each; default 48)")->check(CLI::Range(1, 1000));
  app.add_option("--landmark-error-mm", rq.loads.landmark_error_mm,
                 "loads: RMS error (mm) of the touched landmarks; the landmarks then pull the fit with that weight (default 3; 0: not used by the fit)")
      ->check(CLI::Range(0.0, 50.0));
  app.add_option("--prior-strain", rq.loads.prior_strain,
                 "loads: RMS strain of the deformation prior (regularisation noise^2 / (sum(E V) strain^2)); 0: discrepancy principle")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--model", rq.nonrigid.model_kind, "energy: tissue model for the non-rigid stage (default: the scene's)");
  auto* noise_opt = app.add_option("--noise-mm", noise_mm,
                                   "expected point noise (mm): sets the loads prior's regularisation (noise^2) and the residual the energy schedule "
                                   "stops at (default: estimated from the points, each point's distance to the plane of its neighbours)")
                        ->check(CLI::Range(0.0, 20.0));
  app.add_flag("--scene-boundary", scene_boundary, "hold the scene's fixed vertices at their rest positions during the non-rigid stage");
  app.add_flag("--anchored-boundary", rq.nonrigid.anchored_boundary, "free fit, then the rigid part corrected by the fixed vertices' motion and a second fit holding them");
  app.add_flag("--gravity-change", rq.nonrigid.estimate_gravity_change, "with a held boundary: fit a change of gravity (3 numbers) before the non-rigid fit");
  bool no_self_contact = false;
  app.add_flag("--no-self-contact", no_self_contact, "switch the self-contact term off (lobes may then pass through each other)");
  app.add_option("--schedule", rq.nonrigid.data_weight_schedule, "data weights, stiff to flexible (default 4 16 64 256 1024 4096)")
      ->check(CLI::PositiveNumber);
  app.add_option("--keep-fraction", rq.icp.keep_fraction, "fraction of the closest points kept (trimming)")->check(CLI::Range(0.3, 1.0));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  rq.nonrigid.noise_mm = noise_mm;
  rq.estimate_noise = noise_opt->count() == 0;
  rq.prior.enabled = !no_pose_prior;
  rq.prior.landmark_error_mm = rq.loads.landmark_error_mm > 0 ? rq.loads.landmark_error_mm : 3.0;
  rq.nonrigid.keep_fraction = rq.icp.keep_fraction;
  rq.nonrigid.scene_boundary = scene_boundary;
  rq.nonrigid.self_contact = !no_self_contact;
  rq.rigid_only = in.rigid_only;
  if (in.surface_path.empty() && in.lcm_url.empty()) {
    std::cerr << "arnav-register: give the intraoperative points: --surface FILE, or --lcm URL for a live swab (run with --help)\n";
    return 2;
  }
  const char* me = "arnav-register: ";

  // ---- inputs (exit 2 on anything wrong, naming file and line) ----
  Scene scene;
  PointCloud cloud;
  std::vector<NamedPoint> targets;
  Embedding target_embedding;
  try {
    scene = load_scene(in.scene_path);
    if (!in.lcm_url.empty()) {
      cloud = collect_swab(in);
      in.surface_path = in.out_dir + "/swab.xyz";  // written below, with the other outputs
    } else {
      cloud = read_point_cloud(in.surface_path);
    }
    const double model_extent = bounding_extent_mm(scene.organ_surface.positions_World_mm);
    check_cloud_units(cloud, model_extent);
    if (!in.landmarks_path.empty()) {
      rq.landmarks = read_landmarks(in.landmarks_path);
      try {
        register_landmarks(rq.landmarks);
      } catch (const std::invalid_argument& e) {
        throw_load_error(in.landmarks_path, 0, e.what(), "touch at least 3 landmarks that are not on one line");
      }
    }
    if (in.pose_path == "identity") {
      rq.X_IntraopModel_initial = Eigen::Isometry3d::Identity();
      rq.initial_pose_name = "identity";
    } else if (!in.pose_path.empty()) {
      try {
        rq.X_IntraopModel_initial = arnav::calib::read_transform(in.pose_path, "X_IntraopModel").X_ParentChild;
      } catch (const std::exception& e) {
        throw LoadError(e.what());
      }
    }
    if (!in.targets_path.empty()) {
      targets = read_targets(in.targets_path);
      Eigen::Matrix3Xd p(3, static_cast<Eigen::Index>(targets.size()));
      for (std::size_t i = 0; i < targets.size(); ++i) {
        // one by one, so the error names the target and its line
        try {
          embed_points(scene.problem.mesh, Eigen::Matrix3Xd(targets[i].p_mm), 1.0, "target");
        } catch (const LoadError&) {
          throw_load_error(in.targets_path, targets[i].line,
                           "target '" + targets[i].name + "' lies outside the organ of " + in.scene_path + " (more than 1 mm)",
                           "give targets in the scene (Model) frame, inside or on the organ");
        }
        p.col(static_cast<Eigen::Index>(i)) = targets[i].p_mm;
      }
      target_embedding = embed_points(scene.problem.mesh, p, 1.0, "target");
    }
    if (cloud.size() == 0 && rq.landmarks.empty() && !rq.X_IntraopModel_initial)
      throw_load_error(in.surface_path, 0, "the cloud is empty and no landmarks or initial pose were given: nothing to register",
                       "give a surface with points, or --landmarks / --initial-pose");
  } catch (const LoadError& e) {
    std::cerr << me << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << me << e.what() << "\n";
    return 2;
  }
  for (const auto& note : scene.notes) std::cerr << me << note << "\n";
  rq.points_Intraop_mm = cloud.points_mm;
  if (cloud.has_normals()) rq.normals_Intraop = cloud.normals;

  // ---- registration ----
  RegistrationResult r;
  std::string basis_source = "none";  // loads: built | loaded
  double basis_time_s = 0.0;
  std::string basis_file;
  try {
    if (!basis_cache.empty() && !rq.rigid_only && rq.nonrigid_method == "loads") {
      CachedBasis cb = cached_load_basis(scene, rq.basis, basis_cache);
      for (const auto& w : cb.warnings) std::cerr << me << "warning: " << w << "\n";
      rq.prebuilt_basis = cb.basis;
      basis_source = cb.source;
      basis_time_s = cb.time_s;
      basis_file = cb.path;
    }
    r = register_patient(scene, rq);
  } catch (const std::invalid_argument& e) {
    std::cerr << me << in.scene_path << ": the registration could not run: " << e.what() << "\n";
    return 2;
  } catch (const LoadError& e) {
    std::cerr << me << e.what() << "\n";
    return 2;
  }

  if (!rq.rigid_only && rq.nonrigid_method == "loads" && basis_cache.empty()) {
    basis_source = "built";
    basis_time_s = r.basis_time_s;
  } else if (basis_source != "none") {
    // the cached basis was made before register_patient: count its time in the totals
    r.wall_time_s += basis_time_s;
    r.basis_time_s = basis_time_s;
    if (r.nonrigid) r.nonrigid->wall_time_s += basis_time_s;
  }

  // ---- outputs ----
  int exit_code = 0;
  std::vector<std::string> problems;
  const bool have_points = cloud.size() > 0;
  const std::string& term = r.icp.summary.termination;
  const bool icp_failed = term.rfind("too few inliers", 0) == 0 || term == "numerical failure";
  if (have_points && icp_failed) {
    problems.push_back("surface rigid registration failed: " + term + "; the " + r.initialisation + " pose is kept");
    exit_code = 1;
  } else if (have_points && term != "converged" && !r.prior) {
    // without a prior nothing judges a pose that did not converge
    problems.push_back("surface rigid registration did not converge: " + term);
    exit_code = 1;
  } else if (have_points && term != "converged") {
    r.notes.push_back("surface rigid stopped (" + term + "); judged against the " + r.prior->source + " prior: " + r.kept_reason);
  }
  if (r.loads && r.loads->message.find("numerical failure") != std::string::npos) {
    problems.push_back("non-rigid (loads): the fit failed numerically; the rigid result is kept");
    exit_code = 1;
  }
  if (r.nonrigid)
    for (const auto& l : r.nonrigid->levels)
      if (l.termination == "model unhealthy") {
        problems.push_back("non-rigid: " + r.nonrigid->message);
        exit_code = 1;
      }
  try {
    std::filesystem::create_directories(in.out_dir);
    const std::string dir = in.out_dir + "/";
    if (!in.lcm_url.empty()) {  // the live swab, readable back with --surface
      std::ofstream f(dir + "swab.xyz");
      f.precision(10);
      f << "# arnav-register live swab from " << in.lcm_url << " " << in.cloud_channel << ", frame " << cloud.frame_name << " (mm)\n";
      for (int i = 0; i < cloud.size(); ++i) {
        f << cloud.points_mm(0, i) << ' ' << cloud.points_mm(1, i) << ' ' << cloud.points_mm(2, i);
        if (cloud.has_normals()) f << ' ' << cloud.normals(0, i) << ' ' << cloud.normals(1, i) << ' ' << cloud.normals(2, i);
        f << '\n';
      }
      if (!f) throw LoadError(dir + "swab.xyz: write failed. Fix: check free disk space");
    }
    // deformed display surface in Intraop
    const Eigen::Matrix3Xd organ_Intraop = r.X_IntraopModel * scene.organ_embedding.apply(scene.problem.mesh, r.x_Model_mm);
    write_obj(dir + "registered_organ.obj", organ_Intraop, scene.organ_surface.tris);
    // residual per point at the result
    std::vector<double> residual;
    double rms = 0.0;
    if (have_points) {
      rms = surface_rms_mm(scene.problem.mesh, r.x_Model_mm, r.X_IntraopModel.inverse() * cloud.points_mm, rq.icp.keep_fraction,
                           rq.nonrigid.max_distance_mm, &residual);
    }
    arnav::calib::RigidTransformRecord rec;
    rec.parent_frame = "Intraop";
    rec.child_frame = "Model";
    rec.X_ParentChild = r.X_IntraopModel;
    rec.method = "arnav-register: " + r.initialisation + " + point-to-plane ICP" + (r.deformed ? " (rigid part of a non-rigid registration)" : "");
    rec.date = arnav::calib::utc_now_iso8601();
    rec.residuals["surface_rms_mm"] = r.icp.summary.final_rms_mm;
    rec.residuals["surface_max_mm"] = r.icp.summary.final_max_mm;
    if (r.landmarks) rec.residuals["landmark_fre_rms_mm"] = r.landmarks->fit.fre_rms_mm;
    rec.samples = r.icp.summary.points_used;
    arnav::calib::write_transform(dir + "X_IntraopModel.yaml", rec);
    std::vector<NamedPoint> carried = targets;
    if (!targets.empty()) {
      const Eigen::Matrix3Xd p = carry_to_intraop(scene, target_embedding, r);
      for (std::size_t i = 0; i < carried.size(); ++i) carried[i].p_mm = p.col(static_cast<Eigen::Index>(i));
      write_targets(dir + "targets.csv", carried);
    }

    json j;
    j["scene"] = in.scene_path;
    j["surface"] = {{"file", in.surface_path}, {"points", cloud.size()}, {"normals", cloud.has_normals()}};
    j["initialisation"] = r.initialisation;
    j["X_IntraopModel_row_major"] = matrix_json(r.X_IntraopModel);
    json stages = json::array();
    if (r.landmarks) {
      json lm = json::array();
      for (std::size_t i = 0; i < rq.landmarks.size(); ++i)
        lm.push_back({{"name", rq.landmarks[i].name}, {"residual_mm", r.landmarks->fit.residual_mm[i]}});
      stages.push_back({{"stage", "landmarks"},
                        {"iterations", 0},
                        {"fre_rms_mm", r.landmarks->fit.fre_rms_mm},
                        {"reflection_guarded", r.landmarks->fit.reflection_guarded},
                        {"landmarks", lm},
                        {"termination", "closed form"}});
    }
    json icp = icp_json(r.icp.summary);
    icp["stage"] = "surface_rigid";
    stages.push_back(icp);
    if (r.nonrigid) {
      const NonrigidResult& nr = *r.nonrigid;
      json levels = json::array();
      for (const auto& l : nr.levels)
        levels.push_back({{"data_weight", l.data_weight},
                          {"iterations", l.updates},
                          {"model_steps", l.model_steps},
                          {"energy_elastic_mN_mm", l.elastic_energy},
                          {"energy_data_mN_mm", l.data_energy},
                          {"residual_rms_mm", l.rms_mm},
                          {"residual_max_mm", l.max_mm},
                          {"points_used", l.points_used},
                          {"points_trimmed", l.points_trimmed},
                          {"max_displacement_mm", l.max_displacement_mm},
                          {"self_contacts", l.contacts},
                          {"wall_time_s", l.wall_time_s},
                          {"termination", l.termination}});
      stages.push_back({{"stage", "nonrigid"},
                        {"model", nr.model},
                        {"accepted", nr.accepted},
                        {"message", nr.message},
                        {"rigid_residual_rms_mm", nr.rigid_rms_mm},
                        {"residual_rms_mm", nr.final_rms_mm},
                        {"inverted_elements", nr.inverted_elements},
                        {"iterations", static_cast<int>(nr.levels.size())},
                        {"levels", levels},
                        {"wall_time_s", nr.wall_time_s},
                        {"self_collision",
                         rq.nonrigid.self_contact ? json{{"term", "on"}, {"margin_mm", rq.nonrigid.contact_margin_mm}, {"crossed_vertices", nr.crossed_vertices}}
                                                  : json{{"term", "off"}, {"crossed_vertices", nr.crossed_vertices}}},
                        {"gravity_change_mm_s2", {nr.gravity_change_mm_s2.x(), nr.gravity_change_mm_s2.y(), nr.gravity_change_mm_s2.z()}}});
      stages.back()["method"] = rq.nonrigid_method;
      if (r.loads) {
        const LoadFitResult& f = *r.loads;
        json its = json::array();
        for (const auto& it : f.iterations)
          its.push_back({{"residual_rms_mm", it.rms_mm},
                         {"predicted_rms_mm", it.predicted_rms_mm},
                         {"lambda", it.lambda},
                         {"pose_step_mm", it.step_pose_mm},
                         {"shape_step_mm", it.step_shape_mm},
                         {"points_used", it.points_used},
                         {"strain_energy_mN_mm", it.strain_energy}});
        stages.back()["loads"] = {{"basis_modes", r.basis_modes},
                                  {"basis", basis_source},
                                  {"basis_time_s", basis_time_s},
                                  {"fit_time_s", f.wall_time_s},
                                  {"discrepancy_mm", nr.discrepancy_mm},
                                  {"pose_correction_mm", f.D.translation().norm()},
                                  {"pose_correction_deg", rotation_angle_deg(f.D)},
                                  {"max_displacement_mm", f.max_displacement_mm},
                                  {"strain_energy_mN_mm", f.strain_energy},
                                  {"gravity_energy_share", f.gravity_fraction},
                                  {"regularisation", f.prior_lambda > 0 ? "prior" : "discrepancy"},
                                  {"lambda", f.lambda},
                                  {"prior_strain", rq.loads.prior_strain},
                                  {"landmarks_used", f.landmarks_used},
                                  {"landmark_rms_rigid_mm", f.landmark_rigid_rms_mm},
                                  {"landmark_rms_final_mm", f.landmark_final_rms_mm},
                                  {"iterations", its}};
      }
    }
    j["stages"] = stages;
    j["kept_stage"] = r.kept_stage;
    j["kept_reason"] = r.kept_reason;
    j["noise_mm"] = r.noise_mm;
    j["noise_estimated"] = r.noise_estimated;
    j["supports_held"] = r.supports_held;
    if (r.prior) {
      json sd = json::array(), st = json::array();
      for (int i = 0; i < 3; ++i) {
        sd.push_back(std::sqrt(r.prior->covariance(i, i)) * 180.0 / 3.14159265358979323846);
        st.push_back(std::sqrt(r.prior->covariance(i + 3, i + 3)));
      }
      j["pose_prior"] = {{"source", r.prior->source},
                         {"rotation_sigma_deg", sd},
                         {"translation_sigma_mm", st},
                         {"centre_Model_mm", {r.prior->centre_Model_mm.x(), r.prior->centre_Model_mm.y(), r.prior->centre_Model_mm.z()}}};
    } else {
      j["pose_prior"] = nullptr;
    }
    if (r.posterior.valid) {
      const PosePosterior& p = r.posterior;
      j["pose_posterior"] = {{"rotation_sigma_deg", {p.rotation_sigma_deg.x(), p.rotation_sigma_deg.y(), p.rotation_sigma_deg.z()}},
                             {"translation_sigma_mm", {p.translation_sigma_mm.x(), p.translation_sigma_mm.y(), p.translation_sigma_mm.z()}},
                             {"deviation_from_prior_sigmas", p.deviation_sigmas},
                             {"unconstrained_directions", p.unconstrained_text}};
    }
    // the load basis: built here or loaded from --basis-cache (time: build, or read + check)
    j["basis"] = basis_source;
    j["basis_time_s"] = basis_time_s;
    if (!basis_file.empty()) j["basis_cache_file"] = basis_file;
    j["deformed"] = r.deformed;
    j["residual_rms_mm"] = rms;
    j["wall_time_s"] = r.wall_time_s;
    j["notes"] = r.notes;
    j["problems"] = problems;
    j["exit_code"] = exit_code;
    {
      std::ofstream f(dir + "summary.json");
      f << j.dump(2) << "\n";
      if (!f) throw LoadError(dir + "summary.json: write failed. Fix: check free disk space");
    }

    std::ostringstream rep;
    rep << "arnav-register report (" << rec.date << ")\n"
        << "scene: " << in.scene_path << " (" << scene.problem.mesh.num_vertices() << " vertices, " << scene.problem.mesh.num_tets()
        << " tets, model " << scene.model.kind << ")\n"
        << "surface: " << in.surface_path << ", " << cloud.size() << " points" << (cloud.has_normals() ? " with normals" : "") << "\n"
        << "initialisation: " << r.initialisation << "\n";
    if (r.landmarks) {
      rep << "landmarks: " << rq.landmarks.size() << ", FRE " << r.landmarks->fit.fre_rms_mm << " mm RMS";
      // three points are always coplanar, so their unconstrained fit can be a reflection
      // without any mismatch: warn from four landmarks on
      if (r.landmarks->fit.reflection_guarded && rq.landmarks.size() >= 4)
        rep << " (WARNING: reflection guarded - landmark pairs probably mismatched)";
      rep << "\n";
      for (std::size_t i = 0; i < rq.landmarks.size(); ++i)
        rep << "  " << rq.landmarks[i].name << ": residual " << r.landmarks->fit.residual_mm[i] << " mm\n";
    }
    rep << "surface rigid (point-to-plane ICP): " << r.icp.summary.termination << " after " << r.icp.summary.iterations
        << " iterations, residual " << r.icp.summary.final_rms_mm << " mm RMS / " << r.icp.summary.final_max_mm << " mm max, "
        << r.icp.summary.points_used << " points used, " << r.icp.summary.points_trimmed << " trimmed, " << r.icp.summary.wall_time_s << " s\n";
    if (r.prior)
      rep << "pose prior: " << r.prior->source << ", 1 sigma " << std::sqrt(r.prior->covariance.topLeftCorner<3, 3>().trace() / 3.0) * 180.0 / 3.14159265358979323846
          << " deg / " << std::sqrt(r.prior->covariance.bottomRightCorner<3, 3>().trace() / 3.0) << " mm (RMS over the axes)\n";
    else
      rep << "pose prior: none (" << (no_pose_prior ? "--no-pose-prior" : "no landmarks and no --initial-pose: the identity is only where ICP starts") << ")\n";
    rep << "point noise: " << r.noise_mm << " mm" << (r.noise_estimated ? " (estimated from the points)" : " (given)") << "\n";
    if (r.posterior.valid) {
      rep << "pose posterior: rotation sigma " << r.posterior.rotation_sigma_deg.transpose() << " deg, translation sigma "
          << r.posterior.translation_sigma_mm.transpose() << " mm; " << r.posterior.deviation_sigmas << " sigmas from the prior\n";
      for (const auto& t : r.posterior.unconstrained_text)
        rep << "  not constrained by the surface" << (r.prior ? " (held by the prior)" : "") << ": " << t << "\n";
    }
    rep << "kept: " << r.kept_stage << " - " << r.kept_reason << "\n";
    rep << "rigid pose X_IntraopModel: rotation " << rotation_angle_deg(r.X_IntraopModel) << " deg, translation "
        << r.X_IntraopModel.translation().transpose() << " mm\n";
    if (r.nonrigid) {
      const NonrigidResult& nr = *r.nonrigid;
      rep << "non-rigid (" << nr.model << "): " << (nr.accepted ? "accepted" : "not accepted") << ": " << nr.message << "\n"
          << "  residual " << nr.rigid_rms_mm << " mm (rigid) -> " << nr.final_rms_mm << " mm RMS, " << nr.wall_time_s << " s, "
          << nr.inverted_elements << " inverted elements, " << nr.crossed_vertices << " surface vertices inside another part of the organ (self-contact term "
          << (rq.nonrigid.self_contact ? "on" : "off") << ")\n";
      for (const auto& l : nr.levels)
        rep << "  data weight " << l.data_weight << ": " << l.updates << " updates, residual " << l.rms_mm << " mm RMS / " << l.max_mm
            << " mm max, max displacement " << l.max_displacement_mm << " mm, " << l.points_trimmed << " trimmed, " << l.wall_time_s << " s, "
            << l.termination << "\n";
    } else {
      rep << "non-rigid: not run (--rigid-only)\n";
    }
    if (basis_source != "none")
      rep << "load basis: " << basis_source << " in " << basis_time_s << " s" << (basis_file.empty() ? std::string() : " (cache " + basis_file + ")") << "\n";
    rep << "final surface residual: " << rms << " mm RMS over the kept points\n";
    if (!targets.empty()) {
      rep << "targets (Intraop, mm):\n";
      for (std::size_t i = 0; i < carried.size(); ++i)
        rep << "  " << carried[i].name << ": " << carried[i].p_mm.transpose() << " (moved " << (carried[i].p_mm - r.X_IntraopModel * targets[i].p_mm).norm()
            << " mm by the deformation)\n";
    }
    rep << "surface error is not target error: judge a registration by TRE on known targets (docs/register.md)\n";
    for (const auto& p : problems) rep << "NOT CONVERGED: " << p << "\n";
    {
      std::ofstream f(dir + "report.txt");
      f << rep.str();
      if (!f) throw LoadError(dir + "report.txt: write failed. Fix: check free disk space");
    }

    arnav::calib::Chart conv;
    conv.title = "registration convergence";
    conv.x_label = "iteration (ICP) / level (non-rigid)";
    conv.y_label = "surface residual RMS (mm)";
    arnav::calib::PlotSeries s_icp;
    s_icp.name = "rigid ICP (point-to-plane)";
    for (std::size_t i = 0; i < r.icp.summary.history.size(); ++i) {
      s_icp.x.push_back(static_cast<double>(i + 1));
      s_icp.y.push_back(r.icp.summary.history[i].rms_mm);
    }
    conv.series.push_back(s_icp);
    if (r.nonrigid && !r.nonrigid->levels.empty()) {
      arnav::calib::PlotSeries s_nr;
      s_nr.name = "non-rigid per level (distance)";
      s_nr.color = cv::Scalar(40, 160, 40);
      const double x0 = static_cast<double>(r.icp.summary.history.size());
      s_nr.x.push_back(x0);
      s_nr.y.push_back(r.nonrigid->rigid_rms_mm);
      for (std::size_t i = 0; i < r.nonrigid->levels.size(); ++i) {
        s_nr.x.push_back(x0 + static_cast<double>(i + 1));
        s_nr.y.push_back(r.nonrigid->levels[i].rms_mm);
      }
      conv.series.push_back(s_nr);
    }
    if (!conv.series[0].x.empty() || conv.series.size() > 1) arnav::calib::write_chart(dir + "convergence.png", conv);
    if (!residual.empty()) {
      arnav::calib::Chart res;
      res.title = "distance of each point to the registered surface";
      res.x_label = "point index";
      res.y_label = "distance (mm)";
      arnav::calib::PlotSeries s;
      s.name = "points";
      s.style = arnav::calib::SeriesStyle::Points;
      for (std::size_t i = 0; i < residual.size(); ++i) {
        s.x.push_back(static_cast<double>(i));
        s.y.push_back(residual[i]);
      }
      res.series.push_back(s);
      res.reference_y = rq.nonrigid.max_distance_mm;
      res.reference_label = "outlier distance";
      arnav::calib::write_chart(dir + "residuals.png", res);
    }
  } catch (const std::exception& e) {
    std::cerr << me << e.what() << "\n";
    return 2;
  }
  for (const auto& n : r.notes) std::cerr << me << n << "\n";
  for (const auto& p : problems) std::cerr << me << "not converged: " << p << " (files written to " << in.out_dir << ")\n";
  std::cout << "{\"out\":\"" << in.out_dir << "\",\"deformed\":" << (r.deformed ? "true" : "false") << ",\"residual_rms_mm\":"
            << r.icp.summary.final_rms_mm << ",\"wall_time_s\":" << r.wall_time_s << ",\"exit\":" << exit_code << "}\n";
  return exit_code;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-register", [&] { return main_body(argc, argv); });
}
