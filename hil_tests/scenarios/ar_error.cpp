#include "hil_tests/scenarios/ar_error.hpp"

#include <algorithm>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>

#include <opencv2/calib3d.hpp>

#include "appliance/synthetic_camera/ground_truth.hpp"
#include "host/app/session_config.hpp"
#include "host/scene/scene.hpp"

namespace arnav::hil {
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

}  // namespace

ArErrorReport evaluate_ar_error(const std::string& session_path, const std::string& gt_path, const std::string& csv_path) {
  const host::SessionConfig session = host::load_session(session_path);
  if (!session.camera || !session.scene_path || !session.X_RefModel || !session.reference)
    throw std::runtime_error(session_path + ": the AR error needs a session with camera, scene, registration and reference tool");
  const host::Scene scene = host::load_scene(*session.scene_path);
  if (scene.tumours.empty()) throw std::runtime_error(*session.scene_path + ": the scene has no tumour");
  const Eigen::Vector3d c_Model = host::tumour_centroid_World_mm(scene, 0, scene.problem.mesh.rest_positions_World_mm);
  const auto& intr = session.camera->intrinsics;
  const double f = 0.5 * (intr.camera_matrix(0, 0) + intr.camera_matrix(1, 1));

  std::map<std::int64_t, camera_sim::GroundTruthRow> truth, deformed;
  for (const auto& r : camera_sim::read_ground_truth(gt_path)) {
    if (r.board == session.reference->name) truth[r.sequence] = r;
    if (r.board == "target:tumour_centroid") deformed[r.sequence] = r;
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
  std::getline(in, line);  // header
  std::map<std::int64_t, bool> seen;
  int line_no = 1;
  while (std::getline(in, line)) {
    ++line_no;
    const auto f_ = split(line);
    if (f_.size() < 10) throw std::runtime_error(csv_path + ":" + std::to_string(line_no) + ": expected at least 10 columns");
    ++rep.csv_rows;
    ArFrame fr;
    fr.sequence = std::stoll(f_[0]);
    fr.latency_ms = std::stod(f_[5]);
    fr.flags = f_[9];
    fr.own_pose = f_[2] == f_[1];
    seen[fr.sequence] = true;
    const auto t = truth.find(fr.sequence);
    if (t == truth.end()) continue;
    fr.board_visible = t->second.tags_visible >= 4;
    fr.drawn = !f_[6].empty();
    if (fr.drawn) {
      const cv::Point2d drawn(std::stod(f_[6]), std::stod(f_[7]));
      const Eigen::Vector3d p_rigid = t->second.X_CamBoard * *session.X_RefModel * c_Model;
      const cv::Point2d px_rigid = project(p_rigid);
      const auto d = deformed.find(fr.sequence);
      if (rep.phantom && d == deformed.end())
        throw std::runtime_error(gt_path + ": frame " + std::to_string(fr.sequence) + " has the board but no target:tumour_centroid row");
      if (d != deformed.end()) {
        const Eigen::Vector3d p = d->second.X_CamBoard.translation();
        const cv::Point2d px = project(p);
        fr.deformed_truth = true;
        fr.error_px = cv::norm(drawn - px);
        fr.error_mm = fr.error_px * p.z() / f;
        fr.rigid_error_px = cv::norm(px_rigid - px);
        fr.rigid_error_mm = fr.rigid_error_px * p.z() / f;
        fr.tumour_displacement_mm = (p - p_rigid).norm();
      } else {
        fr.error_px = cv::norm(drawn - px_rigid);
        fr.error_mm = fr.error_px * p_rigid.z() / f;
      }
    }
    if (fr.board_visible && !fr.drawn) ++rep.visible_without_overlay;
    if (t->second.tags_visible == 0 && fr.drawn) ++rep.invisible_with_overlay;
    rep.frames.push_back(fr);
  }
  for (const auto& [seq, row] : truth)
    if (!seen.count(seq)) ++rep.missing_in_csv;
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
  if (phantom) {
    j["rigid_overlay"] = {{"what", "a rigid overlay (rest-shape tumour through the registration) against the same deformed truth"},
                          {"ar_error_px", stats(rpx)},
                          {"ar_error_mm", stats(rmm)}};
    j["tumour_displacement_mm"] = stats(disp);
  }
  return j;
}

}  // namespace arnav::hil
