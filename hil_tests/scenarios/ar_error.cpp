#include "hil_tests/scenarios/ar_error.hpp"

#include <algorithm>
#include <fstream>
#include <cmath>
#include <map>
#include <set>
#include <optional>
#include <sstream>
#include <stdexcept>

#include <Eigen/QR>
#include <opencv2/calib3d.hpp>

#include "appliance/synthetic_camera/ground_truth.hpp"
#include "host/app/session_config.hpp"
#include "hil_tests/scenarios/surface_error.hpp"
#include "host/app/tumour_surface_file.hpp"
#include "host/scene/scene.hpp"

namespace arnav::hil {
using host::TriMesh;
namespace {

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5))];
}

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  std::string f;
  while (std::getline(ss, f, ',')) out.push_back(f);
  if (!line.empty() && line.back() == ',') out.emplace_back();
  return out;
}

// The true tumour, for the surface distance: the scene's rest surface and the phantom's
// interior targets at rest in Model (from the first frame with all of them, through the
// true registration; the phantom is at rest there).
struct TrueTumour {
  TriSurface rest_Model;
  std::map<std::string, Eigen::Vector3d> targets_Model;
};

TriSurface to_tri_surface(const host::TriMesh& m) {
  TriSurface s;
  for (Eigen::Index i = 0; i < m.positions_World_mm.cols(); ++i) s.vertices_mm.push_back(m.positions_World_mm.col(i));
  for (const auto& t : m.tris) s.triangles.emplace_back(t[0], t[1], t[2]);
  return s;
}

TrueTumour rest_targets(const std::map<std::int64_t, camera_sim::GroundTruthRow>& board,
                        const std::map<std::int64_t, std::map<std::string, Eigen::Vector3d>>& targets_Cam,
                        const Eigen::Isometry3d& X_RefModel, const host::TriMesh& rest_surface, const std::string& gt_path) {
  TrueTumour t;
  t.rest_Model = to_tri_surface(rest_surface);
  std::size_t most = 0;
  for (const auto& [seq, m] : targets_Cam) most = std::max(most, m.size());
  for (const auto& [seq, m] : targets_Cam) {
    const auto b = board.find(seq);
    if (m.size() != most || b == board.end()) continue;
    const Eigen::Isometry3d X_ModelCam = (b->second.X_CamBoard * X_RefModel).inverse();
    for (const auto& [name, p] : m) t.targets_Model[name] = X_ModelCam * p;
    break;
  }
  if (t.targets_Model.size() < 4)
    throw std::runtime_error(gt_path + ": the tumour surface distance needs >= 4 interior targets (target:* rows of a deforming phantom), found " +
                             std::to_string(t.targets_Model.size()));
  return t;
}

// The rest surface under the least-squares affine map from the rest targets (Model) to the
// frame's targets (Cam); nullopt when the frame lacks a target or they are degenerate.
std::optional<TriSurface> true_tumour_surface_Cam(const TrueTumour& t, const std::map<std::string, Eigen::Vector3d>& frame_Cam) {
  const auto n = static_cast<Eigen::Index>(t.targets_Model.size());
  Eigen::MatrixXd A(n, 4), B(n, 3);
  Eigen::Index i = 0;
  for (const auto& [name, p] : t.targets_Model) {
    const auto q = frame_Cam.find(name);
    if (q == frame_Cam.end()) return std::nullopt;
    A.row(i) << p.x(), p.y(), p.z(), 1.0;
    B.row(i) = q->second.transpose();
    ++i;
  }
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A);
  if (qr.rank() < 4) return std::nullopt;
  const Eigen::MatrixXd M = qr.solve(B);  // 4 x 3: [x y z 1] * M
  TriSurface s = t.rest_Model;
  for (auto& v : s.vertices_mm) v = (Eigen::RowVector4d(v.x(), v.y(), v.z(), 1.0) * M).transpose();
  return s;
}

// Availability: eligible = board clearly visible at or after the first registered frame;
// a frame missing from overlay.csv after that counts as not displayed (a failure).
void count_availability(ArErrorReport& rep, const std::map<std::int64_t, camera_sim::GroundTruthRow>& truth) {
  std::optional<std::int64_t> first_registered;
  std::map<std::int64_t, const ArFrame*> by_seq;
  for (const ArFrame& fr : rep.frames) {
    by_seq[fr.sequence] = &fr;
    if (fr.registered && (!first_registered || fr.sequence < *first_registered)) first_registered = fr.sequence;
  }
  if (!first_registered) return;
  for (const auto& [seq, row] : truth) {
    if (seq < *first_registered || row.tags_visible < 4) continue;
    ++rep.availability.eligible;
    const auto it = by_seq.find(seq);
    if (it == by_seq.end()) {
      ++rep.availability.not_displayed;
      rep.eligible_not_displayed.push_back(seq);
    } else if (it->second->drawn) {
      ++rep.availability.with_overlay;
    } else {
      ++rep.availability.not_drawn;
    }
  }
}

}  // namespace

std::optional<double> quantile_counting_missing(std::vector<double> values, std::int64_t missing, double q) {
  const std::size_t n = values.size() + static_cast<std::size_t>(std::max<std::int64_t>(0, missing));
  if (n == 0) return std::nullopt;
  std::sort(values.begin(), values.end());
  const auto rank = std::min(n - 1, static_cast<std::size_t>(q * static_cast<double>(n - 1) + 0.5));
  if (rank >= values.size()) return std::nullopt;
  return values[rank];
}

ArErrorReport evaluate_ar_error(const std::string& session_path, const std::string& gt_path, const std::string& csv_path,
                                const std::string& surfaces_path) {
  const host::SessionConfig session = host::load_session(session_path);
  if (!session.camera || !session.scene_path || !session.X_RefModel || !session.reference)
    throw std::runtime_error(session_path + ": the AR error needs a session with camera, scene, registration and reference tool");
  const host::Scene scene = host::load_scene(*session.scene_path);
  if (scene.tumours.empty()) throw std::runtime_error(*session.scene_path + ": the scene has no tumour");
  const Eigen::Vector3d c_Model = host::tumour_centroid_World_mm(scene, 0, scene.problem.mesh.rest_positions_World_mm);
  const auto& intr = session.camera->intrinsics;
  const double f = 0.5 * (intr.camera_matrix(0, 0) + intr.camera_matrix(1, 1));

  std::map<std::int64_t, camera_sim::GroundTruthRow> truth, deformed;
  std::map<std::int64_t, std::map<std::string, Eigen::Vector3d>> targets_Cam;  // per frame: target name -> Cam
  for (const auto& r : camera_sim::read_ground_truth(gt_path)) {
    if (r.board == session.reference->name) truth[r.sequence] = r;
    if (r.board == "target:tumour_centroid") deformed[r.sequence] = r;
    if (r.board.rfind("target:", 0) == 0) targets_Cam[r.sequence][r.board] = r.X_CamBoard.translation();
  }
  std::map<std::int64_t, TriMesh> drawn_surfaces;
  TrueTumour true_tumour;
  if (!surfaces_path.empty()) {
    drawn_surfaces = host::read_tumour_surfaces(surfaces_path);
    true_tumour = rest_targets(truth, targets_Cam, *session.X_RefModel, scene.tumours[0].rest, gt_path);
  }
  ArErrorReport rep;
  rep.phantom = !deformed.empty();
  const auto project = [&](const Eigen::Vector3d& p) {
    std::vector<cv::Point3d> pts{{p.x(), p.y(), p.z()}};
    std::vector<cv::Point2d> px;
    cv::projectPoints(pts, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cv::Mat(intr.camera_matrix), intr.distortion_mat(), px);
    return px[0];
  };
  rep.truth_frames = static_cast<std::int64_t>(truth.size());
  std::ifstream in(csv_path);
  if (!in) throw std::runtime_error(csv_path + ": cannot read the overlay CSV");
  std::string line;
  std::getline(in, line);  // header: columns by name (older files lack the 3-D centroid)
  const std::vector<std::string> header = split(line);
  const auto column = [&](const std::string& name, bool required) {
    for (std::size_t i = 0; i < header.size(); ++i)
      if (header[i] == name) return static_cast<int>(i);
    if (required) throw std::runtime_error(csv_path + ":1: no column '" + name + "' (an overlay.csv written by arnav-host --record)");
    return -1;
  };
  const int i_seq = column("camera_sequence", true), i_pose = column("pose_time_mono_us", true),
            i_capture = column("capture_time_mono_us", true), i_lat = column("motion_to_photon_ms", true),
            i_u = column("tumour_u_px", true), i_v = column("tumour_v_px", true), i_flags = column("flags", true),
            i_x = column("tumour_x_cam_mm", false), i_y = column("tumour_y_cam_mm", false), i_z = column("tumour_z_cam_mm", false);
  rep.has_3d = i_x >= 0 && i_y >= 0 && i_z >= 0;
  const int needed = std::max({i_seq, i_pose, i_capture, i_lat, i_u, i_v, i_flags, i_x, i_y, i_z}) + 1;
  std::map<std::int64_t, bool> seen;
  int line_no = 1;
  while (std::getline(in, line)) {
    ++line_no;
    const auto f_ = split(line);
    const auto cell = [&](int i) -> const std::string& { return f_[static_cast<std::size_t>(i)]; };
    if (static_cast<int>(f_.size()) < needed)
      throw std::runtime_error(csv_path + ":" + std::to_string(line_no) + ": expected at least " + std::to_string(needed) + " columns");
    ++rep.csv_rows;
    ArFrame fr;
    try {
      fr.sequence = std::stoll(cell(i_seq));
      fr.latency_ms = std::stod(cell(i_lat));
    } catch (const std::exception&) {
      throw std::runtime_error(csv_path + ":" + std::to_string(line_no) + ": camera_sequence / motion_to_photon_ms is not a number");
    }
    fr.flags = cell(i_flags);
    fr.registered = fr.flags.find("unregistered") == std::string::npos;
    fr.own_pose = cell(i_pose) == cell(i_capture);
    seen[fr.sequence] = true;
    const auto t = truth.find(fr.sequence);
    if (t == truth.end()) continue;
    fr.board_visible = t->second.tags_visible >= 4;
    fr.drawn = !cell(i_u).empty();
    if (fr.drawn) {
      const cv::Point2d drawn(std::stod(cell(i_u)), std::stod(cell(i_v)));
      const Eigen::Vector3d p_rigid = t->second.X_CamBoard * *session.X_RefModel * c_Model;
      const cv::Point2d px_rigid = project(p_rigid);
      const auto d = deformed.find(fr.sequence);
      if (rep.phantom && d == deformed.end())
        throw std::runtime_error(gt_path + ": frame " + std::to_string(fr.sequence) + " has the board but no target:tumour_centroid row");
      Eigen::Vector3d p_true = p_rigid;
      if (d != deformed.end()) {
        const Eigen::Vector3d p = d->second.X_CamBoard.translation();
        const cv::Point2d px = project(p);
        fr.deformed_truth = true;
        fr.error_px = cv::norm(drawn - px);
        fr.error_mm = fr.error_px * p.z() / f;
        fr.rigid_error_px = cv::norm(px_rigid - px);
        fr.rigid_error_mm = fr.rigid_error_px * p.z() / f;
        fr.tumour_displacement_mm = (p - p_rigid).norm();
        p_true = p;
      } else {
        fr.error_px = cv::norm(drawn - px_rigid);
        fr.error_mm = fr.error_px * p_rigid.z() / f;
      }
      if (rep.has_3d && !cell(i_x).empty()) {
        const Eigen::Vector3d drawn_Cam(std::stod(cell(i_x)), std::stod(cell(i_y)), std::stod(cell(i_z)));
        const CentroidError3d e = centroid_error_3d(drawn_Cam, p_true);
        fr.has_3d = true;
        fr.error_3d_mm = e.distance_mm;
        fr.error_depth_mm = e.along_ray_mm;
        fr.error_lateral_mm = e.across_ray_mm;
      }
    }
    const auto surf = drawn_surfaces.find(fr.sequence);
    const auto tg = targets_Cam.find(fr.sequence);
    if (fr.drawn && surf != drawn_surfaces.end() && tg != targets_Cam.end()) {
      if (const auto truth_surface = true_tumour_surface_Cam(true_tumour, tg->second)) {
        const SurfaceDistance sd = surface_distance(to_tri_surface(surf->second), *truth_surface);
        fr.has_surface = true;
        fr.surface_mean_mm = sd.mean_mm;
        fr.surface_max_mm = sd.max_mm;
        rep.has_surface = true;
      }
    }
    if (fr.board_visible && !fr.drawn) ++rep.visible_without_overlay;
    if (t->second.tags_visible == 0 && fr.drawn) ++rep.invisible_with_overlay;
    rep.frames.push_back(fr);
  }
  for (const auto& [seq, row] : truth) {
    rep.truth_sequences.push_back(seq);
    if (!seen.count(seq)) ++rep.missing_in_csv;
  }
  count_availability(rep, truth);
  return rep;
}

nlohmann::json ArErrorReport::summary() const {
  std::vector<double> px, mm, lat, rpx, rmm, disp;
  for (const auto& f : frames) {
    if (f.drawn) {
      px.push_back(f.error_px);
      mm.push_back(f.error_mm);
      if (f.deformed_truth) {
        rpx.push_back(f.rigid_error_px);
        rmm.push_back(f.rigid_error_mm);
        disp.push_back(f.tumour_displacement_mm);
      }
    }
    lat.push_back(f.latency_ms);
  }
  const auto mean = [](const std::vector<double>& v) {
    double s = 0;
    for (double x : v) s += x;
    return v.empty() ? 0.0 : s / static_cast<double>(v.size());
  };
  const auto stats = [&](const std::vector<double>& v) {
    return nlohmann::json{{"mean", mean(v)}, {"p95", quantile(v, 0.95)}, {"max", v.empty() ? 0.0 : *std::max_element(v.begin(), v.end())}};
  };
  nlohmann::json j{{"frames_evaluated", px.size()},
          {"truth", phantom ? "deforming phantom (deformed tumour centroid per frame)" : "rigid (scene tumour through the registration)"},
          {"ar_error_px", {{"mean", mean(px)}, {"p95", quantile(px, 0.95)}, {"max", px.empty() ? 0.0 : *std::max_element(px.begin(), px.end())}}},
          {"ar_error_mm", {{"mean", mean(mm)}, {"p95", quantile(mm, 0.95)}, {"max", mm.empty() ? 0.0 : *std::max_element(mm.begin(), mm.end())}}},
          {"motion_to_photon_ms", {{"p50", quantile(lat, 0.5)}, {"p99", quantile(lat, 0.99)}}},
          {"truth_frames", truth_frames},
          {"csv_rows", csv_rows},
          {"missing_in_csv", missing_in_csv},
          {"visible_without_overlay", visible_without_overlay},
          {"invisible_with_overlay", invisible_with_overlay}};
  j["availability"] = {{"what", "frames with the board clearly visible at or after the first registered frame; a frame without an overlay "
                               "(not drawn, or not displayed at all) is a failure"},
                      {"eligible_frames", availability.eligible},
                      {"with_overlay", availability.with_overlay},
                      {"not_drawn", availability.not_drawn},
                      {"not_displayed", availability.not_displayed},
                      {"percent", availability.percent()}};
  if (has_3d) {
    std::vector<double> e3, depth, lateral, e3_eligible;
    std::set<std::int64_t> eligible_drawn;
    for (const auto& f : frames) {
      if (!f.has_3d) continue;
      e3.push_back(f.error_3d_mm);
      depth.push_back(std::abs(f.error_depth_mm));
      lateral.push_back(f.error_lateral_mm);
    }
    const auto or_null = [](std::optional<double> v) { return v ? nlohmann::json(*v) : nlohmann::json(nullptr); };
    const std::int64_t failures = availability.eligible - availability.with_overlay;
    j["ar_error_3d_mm"] = {{"what", "|drawn - true| tumour centroid in the camera frame (3-D), frames with an overlay"},
                           {"frames", e3.size()},
                           {"mean", mean(e3)},
                           {"p95", quantile(e3, 0.95)},
                           {"max", e3.empty() ? 0.0 : *std::max_element(e3.begin(), e3.end())},
                           {"along_ray_abs", stats(depth)},
                           {"across_ray", stats(lateral)},
                           {"counting_missing", {{"what", "the same with each eligible frame without an overlay counted as an infinite error (null: "
                                                          "the quantile falls on a missing frame)"},
                                                 {"missing", failures},
                                                 {"p50", or_null(quantile_counting_missing(e3, failures, 0.5))},
                                                 {"p95", or_null(quantile_counting_missing(e3, failures, 0.95))}}}};
  }
  if (has_surface) {
    std::vector<double> smean, smax;
    for (const auto& f : frames)
      if (f.has_surface) {
        smean.push_back(f.surface_mean_mm);
        smax.push_back(f.surface_max_mm);
      }
    j["tumour_surface_mm"] = {{"what", "distance between the drawn and the true tumour surface (vertices to the other surface, both ways), per frame; "
                                       "the true surface is the scene's rest tumour under the affine map of the phantom's interior targets"},
                              {"frames", smean.size()},
                              {"mean_distance", stats(smean)},
                              {"max_distance", stats(smax)}};
  }
  if (phantom) {
    j["rigid_overlay"] = {{"what", "a rigid overlay (rest-shape tumour through the registration) against the same deformed truth"},
                          {"ar_error_px", stats(rpx)},
                          {"ar_error_mm", stats(rmm)}};
    j["tumour_displacement_mm"] = stats(disp);
  }
  return j;
}

std::string ArErrorReport::frames_csv() const {
  std::ostringstream os;
  os << "sequence,displayed,board_visible,registered,drawn,error_px,error_2d_mm,error_3d_mm,error_along_ray_mm,error_across_ray_mm,surface_mean_mm,surface_max_mm\n";
  std::map<std::int64_t, const ArFrame*> by_seq;
  for (const auto& f : frames) by_seq[f.sequence] = &f;
  for (const std::int64_t seq : truth_sequences) {
    const auto it = by_seq.find(seq);
    if (it == by_seq.end()) {
      os << seq << ",0,,,0,,,,,,,\n";
      continue;
    }
    const ArFrame& f = *it->second;
    os << seq << ",1," << f.board_visible << ',' << f.registered << ',' << f.drawn << ',';
    if (f.drawn) os << f.error_px << ',' << f.error_mm;
    else os << ',';
    os << ',';
    if (f.has_3d) os << f.error_3d_mm << ',' << f.error_depth_mm << ',' << f.error_lateral_mm;
    else os << ",,";
    os << ',';
    if (f.has_surface) os << f.surface_mean_mm << ',' << f.surface_max_mm;
    else os << ',';
    os << "\n";
  }
  return os.str();
}

}  // namespace arnav::hil
