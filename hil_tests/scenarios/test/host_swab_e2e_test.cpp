// arnav-host's swab registration with the real processes (docs/overlay.md "Swab
// registration", docs/hil.md): arnav-polaris-sim (started by the appliance, port: sim)
// moves the pointer over the coarse liver's surface on a scripted path (four landmark
// dwells, then a raster over the anterior surface) with a static reference tool;
// arnav-can-sim serves the foot pedal through the bench's can_shim; arnav-appliance tracks
// both tools (published in Ref), reads the pedal and, with `swab: {input: pedal_cut}`,
// publishes the pointer's tip as point_cloud_t only while that pedal is held; arnav-host
// takes the landmarks on pedal_accept presses (the landmark file carries 1.5-3 mm touch
// errors, so the landmark pose is off), collects the swab and, on the next accept press,
// refines the registration. Checked: cloud messages arrive only while the pedal is held
// and every point lies on the part of the path travelled while it was held (the
// pedal-held swab end to end); the session's registration after the swab is within
// 1 mm of the truth at the tumour and better than the landmark pose.
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>

#include "arnav/point_cloud_t.hpp"
#include "arnav/tool_pose_t.hpp"
#include "hil_tests/bench/child_process.hpp"
#include "hil_tests/bench/namespaces.hpp"
#include "hil_tests/scenarios/can_run.hpp"
#include "hil_tests/scenarios/host_run.hpp"
#include "host/scene/scene.hpp"
#include "protocol/channels.hpp"
#include "protocol/clock.hpp"
#include "protocol/testing/child_process.hpp"
#include "hil_tests/bench/bench_required.hpp"

namespace arnav::hil {
namespace {

constexpr double kRate = 60.0;
constexpr double kFirstFrame = 1000.0;  // the simulator's first frame number (scenario default): path time 0

struct PathRow {
  double t_s;
  Eigen::Vector3d p_Model_mm;
};

// What the test hears on the bus itself: the pointer's poses (path time from the frame
// counter) and the swab messages with their arrival times.
class Listener {
 public:
  explicit Listener(const std::string& url) : bus_(url) {
    if (!bus_.good()) return;
    bus_.subscribe(channels::pose("pointer"), &Listener::on_pose, this);
    bus_.subscribe(channels::cloud("pointer"), &Listener::on_cloud, this);
    thread_ = std::thread([this] {
      while (!stop_.load()) bus_.handleTimeout(20);
    });
  }
  ~Listener() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }
  bool good() const { return thread_.joinable(); }
  // Path time of the newest pointer pose (-1: none yet).
  double path_time_s() const {
    std::lock_guard lock(mutex_);
    return newest_frame_ < 0 ? -1.0 : (static_cast<double>(newest_frame_) - kFirstFrame) / kRate;
  }
  std::vector<std::pair<point_cloud_t, std::int64_t>> clouds() const {
    std::lock_guard lock(mutex_);
    return clouds_;
  }

 private:
  void on_pose(const lcm::ReceiveBuffer*, const std::string&, const tool_pose_t* m) {
    std::lock_guard lock(mutex_);
    newest_frame_ = std::max(newest_frame_, m->device_frame_number);
  }
  void on_cloud(const lcm::ReceiveBuffer*, const std::string&, const point_cloud_t* m) {
    std::lock_guard lock(mutex_);
    clouds_.emplace_back(*m, monotonic_us());
  }
  lcm::LCM bus_;
  std::atomic<bool> stop_{false};
  mutable std::mutex mutex_;
  std::int64_t newest_frame_ = -1;
  std::vector<std::pair<point_cloud_t, std::int64_t>> clouds_;
  std::thread thread_;
};

// Anterior (normal z > 0.5) vertices of the organ's display surface, with area-weighted normals.
std::vector<Eigen::Vector3d> anterior_vertices(const host::TriMesh& m) {
  Eigen::Matrix3Xd n = Eigen::Matrix3Xd::Zero(3, m.positions_World_mm.cols());
  for (const auto& t : m.tris) {
    const Eigen::Vector3d a = m.positions_World_mm.col(t[0]), b = m.positions_World_mm.col(t[1]), c = m.positions_World_mm.col(t[2]);
    const Eigen::Vector3d fn = (b - a).cross(c - a);
    for (int v : t) n.col(v) += fn;
  }
  std::vector<Eigen::Vector3d> out;
  for (Eigen::Index i = 0; i < n.cols(); ++i)
    if (n.col(i).norm() > 0 && n.col(i).normalized().z() > 0.5) out.push_back(m.positions_World_mm.col(i));
  return out;
}

void write_path(const std::filesystem::path& file, const std::vector<PathRow>& rows) {
  std::ofstream out(file);
  out << "t_s,x_mm,y_mm,z_mm\n";
  out.precision(10);
  for (const auto& r : rows) out << r.t_s << ',' << r.p_Model_mm.x() << ',' << r.p_Model_mm.y() << ',' << r.p_Model_mm.z() << '\n';
}

std::string matrix16(const Eigen::Isometry3d& X) {
  std::string s = "[";
  char v[40];
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) {
      std::snprintf(v, sizeof v, "%s%.10g", r + c == 0 ? "" : ", ", X.matrix()(r, c));
      s += v;
    }
  return s + "]";
}

Eigen::Isometry3d matrix_of(const nlohmann::json& m16) {
  const auto m = m16.get<std::vector<double>>();
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) X.matrix()(r, c) = m[static_cast<std::size_t>(4 * r + c)];
  return X;
}

TEST(HostSwabE2e, PedalHeldSwabRefinesTheLandmarkRegistration) {
  const std::string scene_path = arnav::testing::data_dir() + "/liver/liver_coarse.scene.yaml";
  const host::Scene scene = host::load_scene(scene_path);
  const Eigen::Vector3d tumour_Model = host::tumour_centroid_World_mm(scene, 0, scene.problem.mesh.rest_positions_World_mm);
  const std::vector<Eigen::Vector3d> front = anterior_vertices(scene.organ_surface);
  ASSERT_GT(front.size(), 100u);
  // Four landmarks spread in 3D (as anatomical landmarks are): the surface vertices furthest
  // along +x, -x, +y and +z.
  std::vector<Eigen::Vector3d> landmarks;
  const Eigen::Matrix3Xd& V = scene.organ_surface.positions_World_mm;
  for (const Eigen::Vector3d& dir : {Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(-1, 0, 0), Eigen::Vector3d(0, 1, 0), Eigen::Vector3d(0, 0, 1)}) {
    Eigen::Index best = 0;
    (V.transpose() * dir).maxCoeff(&best);
    landmarks.push_back(V.col(best));
  }
  // The anterior surface seen from +z: the highest surface point above (x, y), if any.
  const auto surface_above = [&](const Eigen::Vector2d& q) -> std::optional<Eigen::Vector3d> {
    std::optional<Eigen::Vector3d> top;
    for (const auto& tr : scene.organ_surface.tris) {
      const Eigen::Vector3d a = V.col(tr[0]), b = V.col(tr[1]), c = V.col(tr[2]);
      const Eigen::Vector2d e1 = (b - a).head<2>(), e2 = (c - a).head<2>(), d = q - a.head<2>();
      const double det = e1.x() * e2.y() - e1.y() * e2.x();
      if (std::abs(det) < 1e-12) continue;
      const double u = (d.x() * e2.y() - d.y() * e2.x()) / det, v = (e1.x() * d.y() - e1.y() * d.x()) / det;
      if (u < 0 || v < 0 || u + v > 1) continue;
      const Eigen::Vector3d p = a + u * (b - a) + v * (c - a);
      if (!top || p.z() > top->z()) top = p;
    }
    return top;
  };
  // The pointer path (tip = tool origin, Model): landmark 0 from boot until 10 s (the
  // appliance brings the simulator up meanwhile), each later one 3 s, 1 s moves; then the
  // raster over the anterior surface.
  std::vector<PathRow> path;
  std::vector<std::pair<double, double>> dwell;  // per landmark: [start, end] path time
  double t = 0.0;
  for (std::size_t i = 0; i < landmarks.size(); ++i) {
    const double hold = i == 0 ? 10.0 : 3.0;
    path.push_back({t, landmarks[i]});
    dwell.emplace_back(t, t + hold);
    t += hold;
    path.push_back({t, landmarks[i]});
    t += 1.0;
  }
  const double swab_start_s = t;
  // The raster: 130 x 100 mm around the anterior surface's middle, rows 10 mm apart,
  // samples 3 mm apart on the surface, 60 mm/s.
  Eigen::Vector2d mid = Eigen::Vector2d::Zero();
  for (const auto& v : front) mid += v.head<2>();
  mid /= static_cast<double>(front.size());
  Eigen::Vector3d last = landmarks.back();
  bool forward = true;
  for (double y = mid.y() - 50; y <= mid.y() + 50; y += 10.0, forward = !forward) {
    for (double k = 0; k <= 130; k += 3.0) {
      const double x = forward ? mid.x() - 65 + k : mid.x() + 65 - k;
      const auto p = surface_above({x, y});
      if (!p || (*p - last).norm() < 0.5) continue;
      t += (*p - last).norm() / 60.0;
      path.push_back({t, *p});
      last = *p;
    }
  }
  const double swab_end_s = t;
  ASSERT_GT(swab_end_s - swab_start_s, 8.0) << "raster too short";

  CanRun run;
  CanRunOptions o;
  o.path = CanPath::SocketCan;
  // Truth: X_NdiRef (static reference tool) and X_RefModel; the simulator moves the pointer
  // by X_NdiModel = X_NdiRef X_RefModel.
  Eigen::Isometry3d X_NdiRef = Eigen::Isometry3d::Identity();
  X_NdiRef.linear() = Eigen::AngleAxisd(0.4, Eigen::Vector3d(0.2, -0.3, 1).normalized()).toRotationMatrix();
  X_NdiRef.translation() = Eigen::Vector3d(60, -40, -1450);
  Eigen::Isometry3d X_RefModel = Eigen::Isometry3d::Identity();
  X_RefModel.linear() = Eigen::AngleAxisd(0.6, Eigen::Vector3d(0.2, 1, 0.3).normalized()).toRotationMatrix();
  X_RefModel.translation() = Eigen::Vector3d(-30, 45, -120);
  const std::string tmp = make_temp_dir("arnav-swab");
  struct Cleanup {  // also when an assertion returns early
    std::string dir;
    ~Cleanup() {
      if (!std::getenv("ARNAV_HIL_KEEP")) std::filesystem::remove_all(dir);
    }
  } cleanup{tmp};
  write_path(tmp + "/pointer_path.csv", path);
  write_path(tmp + "/reference_path.csv", {{0.0, Eigen::Vector3d::Zero()}, {1.0, Eigen::Vector3d::Zero()}});
  const std::string roms = arnav::testing::data_dir() + "/ndi_roms/";
  {
    std::ofstream s(tmp + "/polaris.yaml");
    s << "frame_rate_hz: 60\nfirst_frame: " << static_cast<int>(kFirstFrame) << "\ntools:\n"
      << "  - name: pointer\n    rom: " << roms << "8700340.rom\n"
      << "    motion: {path: " << tmp << "/pointer_path.csv, X_NdiModel: " << matrix16(X_NdiRef * X_RefModel) << "}\n"
      << "  - name: reference\n    rom: " << roms << "8700339.rom\n"
      << "    motion: {path: " << tmp << "/reference_path.csv, X_NdiModel: " << matrix16(X_NdiRef) << "}\n";
  }
  o.extra_config = "port: sim\nrate_hz: 60\nsim_args: [\"--scenario\", \"" + tmp + "/polaris.yaml\"]\n" +
                   "tools:\n  - {name: pointer, rom: " + roms + "8700340.rom}\n  - {name: reference, rom: " + roms + "8700339.rom}\n" +
                   "frames: {reference: Ref, reference_tool: reference}\n" +
                   "swab: {tool: pointer, tip_mm: [0, 0, 0], input: pedal_cut, min_spacing_mm: 1.0, points_per_message: 20}\n";
  // The host first (in the bench's namespaces; it loads the scene and builds the model), so
  // the path's clock, which starts when the appliance boots the simulator, finds it ready.
  ARNAV_BENCH_OR_SKIP(enter_bench_namespaces());
  const std::filesystem::path dir = tmp;
  // The landmark file: where the pointer dwells, with 1.5-3 mm touch errors (Model).
  const std::vector<Eigen::Vector3d> touch_error = {{2.0, -1.5, 1.0}, {-1.5, 2.0, -1.0}, {1.0, 1.5, 2.0}, {-2.0, -1.5, 1.0}};
  {
    std::ofstream lm(dir / "landmarks.csv");
    lm << "name,x_mm,y_mm,z_mm\n";
    for (std::size_t i = 0; i < landmarks.size(); ++i) {
      const Eigen::Vector3d p = landmarks[i] + touch_error[i];
      lm << "L" << i << ',' << p.x() << ',' << p.y() << ',' << p.z() << '\n';
    }
  }
  {
    std::ofstream s(dir / "session.yaml");
    s << "arnav_session_version: 1\nlcm_url: \"" << CanRun::kLcmUrl << "\"\nsecurity: off\nscene: " << scene_path << "\n"
      << "registration:\n  live:\n    landmarks: landmarks.csv\n    pointer: pointer\n    accept: pedal_accept\n    window_ms: 150\n"
      << "    swab: {source: pointer, accept: pedal_accept, min_points: 150}\n"
      << "tools:\n  reference: {name: reference}\n  pointer: {name: pointer}\nmodel: {rate_hz: 30}\n";
  }
  Listener bus(CanRun::kLcmUrl);
  ASSERT_TRUE(bus.good());
  std::unique_ptr<ChildProcess> host;
  ASSERT_TRUE(start_host(dir, host)) << host->log_tail();
  const std::string why = run.start(o);
  ARNAV_BENCH_OR_SKIP(why);
  const auto wait_path = [&](double t_s, double timeout_s) {
    const std::int64_t until = monotonic_us() + static_cast<std::int64_t>(timeout_s * 1e6);
    while (bus.path_time_s() < t_s && monotonic_us() < until) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    return bus.path_time_s() >= t_s;
  };
  const auto click = [&](const std::string& input, std::size_t nth) {
    ASSERT_EQ(run.inject("press " + input), "OK");
    ASSERT_TRUE(run.lcm().wait_for([&](const CanCapture& c) { return c.count_inputs(input, input_event_t::STATE_PRESSED) >= nth; }, 5.0))
        << run.lcm().event_log();
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    ASSERT_EQ(run.inject("release " + input), "OK");
  };
  // Landmarks: accept pressed in the second half of each dwell (the pointer still).
  for (std::size_t i = 0; i < landmarks.size(); ++i) {
    const double at = std::max(dwell[i].first + 0.5 * (dwell[i].second - dwell[i].first), dwell[i].second - 1.5);
    ASSERT_TRUE(wait_path(at, 90.0)) << "no pointer poses at path time " << at << " s (now " << bus.path_time_s() << ")\n" << run.logs();
    ASSERT_LT(bus.path_time_s(), dwell[i].second - 0.4) << "the bench came up too late for landmark " << i << "\n" << host->log_tail();
    std::printf("[ swab-e2e ] landmark %zu accepted at path time %.2f s (dwell %.1f-%.1f s)\n", i, bus.path_time_s(), dwell[i].first,
                dwell[i].second);
    click("pedal_accept", i + 1);
  }
  EXPECT_TRUE(bus.clouds().empty()) << "swab points before the swab pedal was pressed";
  // The swab pedal held over the middle of the raster only.
  const double press_at = swab_start_s + 0.2 * (swab_end_s - swab_start_s);
  const double release_at = swab_start_s + 0.85 * (swab_end_s - swab_start_s);
  ASSERT_TRUE(wait_path(press_at, 60.0));
  const double pressed_path_s = bus.path_time_s();
  const std::int64_t pressed_wall_us = wall_us();
  ASSERT_EQ(run.inject("press pedal_cut"), "OK");
  ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) { return c.count_inputs("pedal_cut", input_event_t::STATE_PRESSED) >= 1; }, 5.0));
  ASSERT_TRUE(wait_path(release_at, 60.0));
  ASSERT_EQ(run.inject("release pedal_cut"), "OK");
  ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) { return c.count_inputs("pedal_cut", input_event_t::STATE_RELEASED) >= 1; }, 5.0));
  const double released_path_s = bus.path_time_s();
  for (const auto& e : run.lcm().inputs())
    if (e.input_name == "pedal_cut" && e.state == input_event_t::STATE_PRESSED)
      std::printf("[ swab-e2e ] the press: the appliance received it %.3f s, decided %.3f s, published %.3f s after the inject (wall)\n",
                  (e.receive_time_wall_us - pressed_wall_us) * 1e-6, (e.receive_time_wall_us + (e.decided_time_mono_us - e.receive_time_mono_us) - pressed_wall_us) * 1e-6,
                  (e.publish_time_wall_us - pressed_wall_us) * 1e-6);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));  // the release flush
  click("pedal_accept", landmarks.size() + 1);
  // The refinement: reported on the host's console (its stdout, read here).
  std::string console;
  bool done = false;
  for (int i = 0; i < 300 && !done; ++i) {
    const auto line = host->read_line(0.1);
    if (!line) continue;
    console += *line + "\n";
    done = line->find("swab registration") != std::string::npos;
  }
  std::printf("[ swab-e2e ] host console:\n%s", console.c_str());
  const auto clouds = bus.clouds();
  ASSERT_EQ(host->stop(15, 30.0), 0) << host->log_tail();
  EXPECT_EQ(run.stop_appliance(), 0) << run.logs();
  ASSERT_TRUE(done) << console << host->log_tail();

  // Points only while the pedal was held: every point lies on the raster where the pointer
  // was between the press and the release (path times from the frame counter when the
  // test pressed/released; 0.25 s for the bus hop and debounce).
  const auto X_ModelRef = (X_RefModel).inverse();
  std::size_t points = 0;
  double t_first = 1e9, t_last = -1e9;
  const auto path_time_of = [&](const Eigen::Vector3d& p_Model, double* dist) {
    double best = 1e9, best_t = -1;
    for (std::size_t i = 1; i < path.size(); ++i) {
      if (path[i].t_s <= swab_start_s) continue;
      const Eigen::Vector3d a = path[i - 1].p_Model_mm, b = path[i].p_Model_mm;
      const double s = (b - a).squaredNorm() > 0 ? std::clamp((p_Model - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0) : 0.0;
      const double d = (a + s * (b - a) - p_Model).norm();
      if (d < best) best = d, best_t = path[i - 1].t_s + s * (path[i].t_s - path[i - 1].t_s);
    }
    *dist = best;
    return best_t;
  };
  for (const auto& [m, arrival] : clouds) {
    if (&m == &clouds.front().first) std::printf("[ swab-e2e ] the first swab point captured %.3f s after the inject\n", (m.capture_time_wall_us - pressed_wall_us) * 1e-6);
    EXPECT_EQ(m.frame_name, "Ref");
    for (const auto& p : m.p_mm) {
      double d = 0;
      const double tp = path_time_of(X_ModelRef * Eigen::Vector3d(p[0], p[1], p[2]), &d);
      EXPECT_LT(d, 1.0) << "a swab point off the pointer's path";
      t_first = std::min(t_first, tp);
      t_last = std::max(t_last, tp);
      ++points;
    }
  }
  std::printf("[ swab-e2e ] pedal held over path time %.2f-%.2f s (raster %.1f-%.1f s); %zu points in %zu messages over path time %.2f-%.2f s\n",
              pressed_path_s, released_path_s, swab_start_s, swab_end_s, points, clouds.size(), t_first, t_last);
  EXPECT_GE(points, 150u);
  EXPECT_GE(t_first, pressed_path_s - 0.05) << "a point from before the pedal was pressed";
  EXPECT_LE(t_first, pressed_path_s + 0.4) << "sampling started late";
  EXPECT_LE(t_last, released_path_s + 0.25) << "a point from after the pedal was released";
  EXPECT_GE(t_last, released_path_s - 0.6) << "sampling stopped early";

  std::ifstream in(dir / "host.json");
  ASSERT_TRUE(in) << host->log_tail();
  const nlohmann::json j = nlohmann::json::parse(in);
  const auto& reg = j["navigation"]["registration"];
  std::printf("[ swab-e2e ] registration %s\n", reg.dump().c_str());
  ASSERT_EQ(reg["method"], "live landmarks + swab") << reg.dump();
  ASSERT_TRUE(reg["done"].get<bool>()) << host->log_tail();
  const auto& sw = reg["swab"];
  ASSERT_TRUE(sw.contains("result")) << sw.dump();
  ASSERT_TRUE(sw["result"]["accepted"].get<bool>()) << sw.dump() << host->log_tail();
  EXPECT_EQ(sw["points_collected"].get<std::size_t>(), points) << "the session took every point the appliance sent";
  const Eigen::Isometry3d X_landmarks = matrix_of(reg["X_RefModel"]);
  const Eigen::Isometry3d X_swab = matrix_of(sw["result"]["X_RefModel"]);
  const double landmark_error = (X_landmarks * tumour_Model - X_RefModel * tumour_Model).norm();
  const double swab_error = (X_swab * tumour_Model - X_RefModel * tumour_Model).norm();
  std::printf("[ swab-e2e ] error at the tumour: landmarks %.2f mm, after the swab %.2f mm\n", landmark_error, swab_error);
  EXPECT_GT(landmark_error, 1.0) << "the touch errors should put the landmark pose off";
  EXPECT_LT(swab_error, 1.0);
  EXPECT_LT(swab_error, 0.5 * landmark_error);
}

}  // namespace
}  // namespace arnav::hil
