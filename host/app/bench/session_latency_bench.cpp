// arnav-host-latency-bench: host processing latency of the navigation session on this
// machine, in process (no LCM, no appliance, no camera): frames (JPEG, width x height) and
// the reference board pose of each are handed to a live NavigationSession at `rate` Hz
// (exposure = publish = receive = hand-over time), while its model runs on the scene at
// model_rate Hz on its own thread. Host processing latency (`host_processing_latency_ms`)
// = frame received -> overlay ready (JPEG decode, poses, overlay render, lens warp,
// composite, text; recording off); `latency` has the host's stages (decode, render,
// display). Exposure to display with a camera, the appliance and the bus:
// hil_tests/scenarios/latency_session.sh (docs/benchmarks.md). Prints JSON: latency,
// frames dropped by the host, model rate and step time.
// --cut (a scene with `cutting:`): the session also has a scalpel whose blade (60 mm,
// upright in Model) circles the first tumour at --cut-radius mm once every --cut-period s,
// 10 mm below its centre, with the pedal (inputs.cut_enable) held: the model is the cut
// session cutting a ring around the tumour while the overlay runs; the JSON adds the
// session's cutting summary (cut area, cut-path error, events).
#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <thread>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "host/app/navigation_session.hpp"
#include "host/mesh/load_error.hpp"
#include "host/scene/scene.hpp"
#include "protocol/clock.hpp"
#include "protocol/pose_convert.hpp"
#include "protocol/guarded_main.hpp"

namespace {
// The first three fields of /proc/loadavg ("" where unreadable).
std::string load_average() {
  std::ifstream in("/proc/loadavg");
  std::string line;
  std::getline(in, line);
  // "1.23 0.98 0.75 2/180 12345": the three averages.
  std::size_t end = 0;
  for (int field = 0; field < 3 && end != std::string::npos; ++field) end = line.find(' ', end + (field > 0 ? 1 : 0));
  return line.substr(0, end);
}
}  // namespace

static int main_body(int argc, char** argv) {
  CLI::App app{"arnav-host-latency-bench: host processing latency (frame received -> overlay ready) of the navigation session (JSON)"};
  std::string scene_path;
  int width = 1280, height = 720;
  double rate = 60.0, model_rate = 60.0, seconds = 20.0;
  app.add_option("--scene", scene_path, "scene (e.g. data/liver/liver.scene.yaml)")->required();
  app.add_option("--width", width)->check(CLI::Range(64, 4096));
  app.add_option("--height", height)->check(CLI::Range(64, 4096));
  app.add_option("--rate", rate, "camera frames per second")->check(CLI::Range(1.0, 240.0));
  app.add_option("--model-rate", model_rate, "model steps per second")->check(CLI::Range(1.0, 1000.0));
  app.add_option("--seconds", seconds)->check(CLI::Range(1.0, 3600.0));
  std::string cpu_partition = "auto";
  app.add_option("--cpu-partition", cpu_partition, "model.cpu_partition: auto (default), on, off")->check(CLI::IsMember({"auto", "on", "off"}));
  bool cut = false;
  double cut_radius = 25.0, cut_period = 20.0;
  app.add_flag("--cut", cut, "scalpel cutting a ring around the first tumour, pedal held (scene with cutting:)");
  app.add_option("--cut-radius", cut_radius, "ring radius around the tumour centre, mm")->check(CLI::Range(1.0, 200.0));
  app.add_option("--cut-period", cut_period, "seconds per turn of the ring")->check(CLI::Range(1.0, 600.0));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  using namespace arnav;
  using namespace arnav::host;
  try {
    auto scene = std::make_unique<Scene>(load_scene(scene_path));
    SessionConfig c;
    c.source = "(bench)";
    c.scene_path = scene_path;
    c.reference = ToolRole{"liver_marker", 100.0};
    CameraSettings cam;
    cam.name = "bench";
    cam.intrinsics.image_width = width;
    cam.intrinsics.image_height = height;
    const double f = 0.85 * width;
    cam.intrinsics.camera_matrix = cv::Matx33d(f, 0, (width - 1) / 2.0, 0, f, (height - 1) / 2.0, 0, 0, 1);
    cam.intrinsics.distortion = {-0.1, 0.02, 0, 0, 0};
    c.camera = cam;
    c.model.rate_hz = model_rate;
    c.model.cpu_partition = cpu_partition;
    const Eigen::Vector3d centre = scene->organ_surface.positions_World_mm.rowwise().mean();
    Eigen::Isometry3d X_RefModel = Eigen::Isometry3d::Identity();
    X_RefModel.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
    X_RefModel.translation() = -(X_RefModel.linear() * centre);
    c.X_RefModel = X_RefModel;
    Eigen::Vector3d tumour = centre;
    if (cut) {
      if (!scene->cutting) throw std::runtime_error(scene_path + ": --cut needs a scene with a 'cutting:' section (docs/cut.md)");
      if (scene->tumours.empty()) throw std::runtime_error(scene_path + ": --cut circles the first tumour: the scene has none");
      tumour = tumour_centroid_World_mm(*scene, 0, scene->problem.mesh.rest_positions_World_mm);
      ScalpelRole scalpel;
      scalpel.name = "scalpel";
      scalpel.stale_after_ms = 100.0;
      scalpel.heel_Tool_mm = Eigen::Vector3d(0, 0, 60);
      c.scalpel = scalpel;
      c.inputs.cut_enable = InputBinding{"pedal", 500.0, 0};
      c.cutting.mode = "input";
    }
    const std::string load_before = load_average();
    SessionOptions o;
    o.threaded = true;
    NavigationSession session(c, std::move(scene), o);
    session.start();
    // A few distinct camera images (noise texture), JPEG as the appliance sends them.
    std::vector<std::vector<std::uint8_t>> jpegs;
    cv::RNG rng(1);
    for (int i = 0; i < 8; ++i) {
      cv::Mat img(height, width, CV_8UC3);
      rng.fill(img, cv::RNG::UNIFORM, 40, 200);
      cv::GaussianBlur(img, img, cv::Size(0, 0), 3.0);
      std::vector<std::uint8_t> buf;
      cv::imencode(".jpg", img, buf, {cv::IMWRITE_JPEG_QUALITY, 80});
      jpegs.push_back(std::move(buf));
    }
    const auto period = std::chrono::duration<double>(1.0 / rate);
    auto next = std::chrono::steady_clock::now();
    const std::int64_t t0 = monotonic_us();
    const int n = static_cast<int>(seconds * rate);
    for (int k = 0; k < n; ++k) {
      std::this_thread::sleep_until(next);
      next += std::chrono::duration_cast<std::chrono::steady_clock::duration>(period);
      const std::int64_t t = monotonic_us();
      const double s = static_cast<double>(k) / rate;
      Eigen::Isometry3d X_CamRef = Eigen::Isometry3d::Identity();
      X_CamRef.linear() = Eigen::AngleAxisd(0.2 * std::sin(s), Eigen::Vector3d::UnitY()).toRotationMatrix();
      X_CamRef.translation() = Eigen::Vector3d(20 * std::sin(0.7 * s), 10 * std::cos(0.5 * s), 450);
      tool_pose_t p{};
      p.tool_name = "liver_marker";
      p.source = tool_pose_t::SOURCE_CAMERA;
      p.frame_parent = "Cam";
      p.frame_child = "Board";
      set_pose(p, X_CamRef);
      p.status = tool_pose_t::STATUS_VALID;
      p.device_frame_number = k;
      p.receive_time_mono_us = t;
      session.on_pose(p, t);
      if (cut) {
        // The scalpel in Ref (the NDI path): upright blade circling the tumour.
        const double a = 2 * M_PI * s / cut_period;
        Eigen::Isometry3d X_ModelTool = Eigen::Isometry3d::Identity();
        X_ModelTool.translation() = tumour + Eigen::Vector3d(cut_radius * std::cos(a), cut_radius * std::sin(a), -10.0);
        tool_pose_t sp = p;
        sp.tool_name = "scalpel";
        sp.source = tool_pose_t::SOURCE_NDI;
        sp.frame_parent = "Ref";
        sp.frame_child = "Tool";
        set_pose(sp, X_RefModel * X_ModelTool);
        session.on_pose(sp, t);
        if (k % 6 == 0) {
          input_event_t in{};
          in.input_name = "pedal";
          in.state = input_event_t::STATE_PRESSED;
          in.cause = k == 0 ? input_event_t::CAUSE_FRAME : input_event_t::CAUSE_STATE;
          in.sequence = 1;
          session.on_input(in, t);
        }
      }
      image_frame_t fr{};
      fr.camera_name = "bench";
      fr.sequence = k;
      fr.capture_time_mono_us = t;  // exposure = publish = receive = hand-over: only the host's stages are measured
      fr.capture_time_wall_us = wall_us();
      fr.publish_time_mono_us = t;
      fr.width = fr.source_width = width;
      fr.height = fr.source_height = height;
      fr.channels = 3;
      fr.encoding = image_frame_t::ENCODING_JPEG;
      fr.data = jpegs[static_cast<std::size_t>(k) % jpegs.size()];
      fr.size = static_cast<std::int32_t>(fr.data.size());
      session.submit_frame(fr, t);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    session.stop();
    nlohmann::json j = session.summary_json(static_cast<double>(monotonic_us() - t0) * 1e-6);
    j.erase("flags");
    j["bench"] = "session_latency";
    j["scene"] = scene_path;
    j["width"] = width;
    j["height"] = height;
    j["rate_hz"] = rate;
    j["model_rate_hz"] = model_rate;
    j["frames_sent"] = n;
    j["load_average"] = {{"before", load_before}, {"after", load_average()}};  // /proc/loadavg: 1, 5, 15 min
    if (cut) {
      j["cut"] = {{"radius_mm", cut_radius}, {"period_s", cut_period}};
      if (j.contains("cutting")) j["cutting"].erase("events");
    }
    std::cout << j.dump(2) << std::endl;
  } catch (const std::exception& e) {
    std::cerr << "arnav-host-latency-bench: " << e.what() << "\n";
    return 2;
  }
  return 0;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-host-latency-bench", [&] { return main_body(argc, argv); });
}
