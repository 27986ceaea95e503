// arnav-igtl on the HIL bench (docs/igtl.md): simulated Polaris -> arnav-appliance -> LCM
// (udpm, private network namespace) -> arnav-igtl -> OpenIGTLink clients on 127.0.0.1.
// Ten clients at once: a raw client that greets like 3D Slicer (a header-version-2 STATUS
// with metadata), eight of Debian's packaged ReceiveClient and one TrackingDataClient
// (openigtlink-examples, built as shipped; they exit 0 even when they fail, so their output
// is checked). Names, matrices against the simulator's ground truth, CRCs, UTC timestamps,
// TDATA; one ReceiveClient is killed mid-stream and must be dropped without disturbing
// the others.
#include <gtest/gtest.h>

#include <signal.h>

#include <cstdio>
#include <fstream>
#include <map>
#include <memory>
#include <regex>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "host/igtl/messages.hpp"
#include "host/igtl/test/test_client.hpp"
#include "hil_tests/scenarios/hil_run.hpp"
#include "protocol/clock.hpp"
#include "hil_tests/bench/bench_required.hpp"

namespace arnav::hil {
namespace {

std::string env_or(const char* name, const char* fallback) {
  const char* v = std::getenv(name);
  return v && *v ? std::string(v) : std::string(fallback);
}

std::string read_file(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::size_t count_of(const std::string& text, const std::string& needle) {
  std::size_t n = 0;
  for (auto pos = text.find(needle); pos != std::string::npos; pos = text.find(needle, pos + needle.size())) ++n;
  return n;
}

struct TransformCheck {
  std::size_t checked = 0, unmatched = 0, mismatches = 0, bad_crc = 0, bad_time = 0;
  std::string first_mismatch;
};

// Each TRANSFORM's timestamp is the pose's receive_time_wall_us: it finds the LCM pose,
// whose frame number finds the simulator's truth for that tool.
TransformCheck check_transforms(const std::vector<igtl::Message>& received, HilRun& run, const TruthTable& truth,
                                std::int64_t t_start_wall_us, std::int64_t t_end_wall_us) {
  const std::map<std::string, std::string> tool_of = {{"PointerToTracker", "pointer"}, {"ReferenceToTracker", "reference"}};
  std::map<std::pair<std::string, std::int64_t>, std::int64_t> frame_of;
  for (const auto& p : run.lcm().poses())
    if (p.msg.status == tool_pose_t::STATUS_VALID) frame_of[{p.msg.tool_name, p.msg.receive_time_wall_us}] = p.msg.device_frame_number;
  TransformCheck c;
  std::map<std::string, std::int64_t> last_time;
  for (const auto& m : received) {
    if (m.header.type != "TRANSFORM") continue;
    const auto u = igtl::test::unpack(m);
    if (!u.crc_ok) {
      ++c.bad_crc;
      continue;
    }
    if (u.wall_us < t_start_wall_us || u.wall_us > t_end_wall_us || u.wall_us < last_time[u.device_name]) ++c.bad_time;
    last_time[u.device_name] = u.wall_us;
    const auto tool = tool_of.find(u.device_name);
    if (tool == tool_of.end()) {
      if (++c.mismatches == 1) c.first_mismatch = "unexpected TRANSFORM name " + u.device_name;
      continue;
    }
    const auto frame = frame_of.find({tool->second, u.wall_us});
    if (frame == frame_of.end()) {
      ++c.unmatched;
      continue;
    }
    const auto t = truth.find({static_cast<std::uint32_t>(frame->second), tool->second});
    if (t == truth.end() || !t->second.valid) {
      ++c.unmatched;
      continue;
    }
    Eigen::Matrix4d expected = Eigen::Matrix4d::Identity();
    expected.topLeftCorner<3, 3>() = t->second.q_NdiTool.normalized().toRotationMatrix();
    expected.topRightCorner<3, 1>() = t->second.p_NdiTool_mm;
    const double dp = (u.matrix.topRightCorner<3, 1>() - expected.topRightCorner<3, 1>()).norm();
    const double dr = (u.matrix.topLeftCorner<3, 3>() - expected.topLeftCorner<3, 3>()).cwiseAbs().maxCoeff();
    // float32 on the wire and in the BX reply: ~1e-4 mm at 1.5 m, ~1e-7 per rotation entry.
    if (dp > 2e-3 || dr > 2e-6) {
      if (++c.mismatches == 1)
        c.first_mismatch = u.device_name + " frame " + std::to_string(frame->second) + ": position off by " + std::to_string(dp) +
                           " mm, rotation by " + std::to_string(dr);
    }
    ++c.checked;
  }
  return c;
}

TEST(HilIgtl, SlicerAndPackagedClientsOnTheBench) {
  HilRun run;
  HilRunOptions o;
  const std::int64_t t0 = monotonic_us();
  const std::int64_t t0_wall = wall_us();
  ARNAV_BENCH_OR_SKIP(run.start(o));
  ASSERT_TRUE(run.wait_all_valid(30, t0, 90.0)) << "no tracking within 90 s\n" << run.logs();

  const std::string dir = run.dir();
  ChildProcess igtl({env_or("ARNAV_IGTL_EXE", ARNAV_IGTL_EXE), "--lcm", HilRun::kLcmUrl, "--security", "off", "--port", "0", "--stats-json", dir + "/igtl_stats.json"},
                    {}, dir + "/igtl.log", true);
  const auto ready = igtl.read_line(30.0);
  ASSERT_TRUE(ready && ready->rfind("READY ", 0) == 0) << igtl.log_tail();
  const int port = std::stoi(ready->substr(6));
  const std::string port_text = std::to_string(port);

  // 1 Slicer-like client + 8 ReceiveClient + 1 TrackingDataClient = 10 at once.
  igtl::test::TestClient slicer(port);
  ASSERT_TRUE(slicer.connected()) << slicer.why();
  ASSERT_TRUE(slicer.send(igtl::test::slicer_v2_status()));
  std::vector<std::unique_ptr<ChildProcess>> receivers;
  for (int i = 0; i < 8; ++i)
    receivers.push_back(std::make_unique<ChildProcess>(
        std::vector<std::string>{env_or("ARNAV_IGTL_RECEIVE_CLIENT", ARNAV_IGTL_RECEIVE_CLIENT), "127.0.0.1", port_text},
        std::vector<std::string>{}, dir + "/receive_client_" + std::to_string(i) + ".log"));
  ChildProcess tracking({env_or("ARNAV_IGTL_TRACKING_CLIENT", ARNAV_IGTL_TRACKING_CLIENT), "127.0.0.1", port_text, "30"}, {},
                        dir + "/tracking_client.log");

  slicer.receive_until(1u << 30, 3.0);
  const std::string killed_log = receivers[0]->log_path();
  const std::size_t killed_lines_before = count_of(read_file(killed_log), "Receiving TRANSFORM");
  receivers[0]->stop(SIGKILL, 5.0);  // killed mid-stream
  const std::int64_t t_kill_wall = wall_us();
  slicer.receive_until(1u << 30, 3.0);
  const std::int64_t t_end_wall = wall_us();
  EXPECT_FALSE(slicer.closed_by_server());
  {  // the killed client was noticed, and it alone
    const std::string ilog = read_file(igtl.log_path());
    EXPECT_EQ(count_of(ilog, " closed: ") + count_of(ilog, " dropped: "), 1u) << ilog;
  }

  for (std::size_t i = 1; i < receivers.size(); ++i) EXPECT_TRUE(receivers[i]->running()) << "ReceiveClient " << i << " ended early";
  EXPECT_TRUE(tracking.running()) << read_file(tracking.log_path());
  for (auto& r : receivers) r->stop(SIGTERM, 5.0);
  tracking.stop(SIGTERM, 5.0);
  EXPECT_EQ(igtl.stop(SIGTERM, 15.0), 0) << igtl.log_tail();
  EXPECT_EQ(run.stop_appliance(), 0) << run.logs();
  EXPECT_EQ(run.stop_simulator(), 0) << run.logs();

  // The Slicer-like client: names, matrices = ground truth, CRCs, UTC timestamps.
  const auto received = slicer.take();
  const auto check = check_transforms(received, run, run.truth(), t0_wall, t_end_wall);
  EXPECT_GE(check.checked, 300u);  // 2 tools x 60 Hz x 6 s, with margin for a loaded machine
  EXPECT_EQ(check.mismatches, 0u) << check.first_mismatch;
  EXPECT_EQ(check.bad_crc, 0u);
  EXPECT_EQ(check.bad_time, 0u);
  EXPECT_LE(check.unmatched, check.checked / 50) << "TRANSFORMs without an LCM pose of the same time";
  std::size_t after_kill = 0;
  for (const auto& m : received)
    if (m.header.type == "TRANSFORM" && igtl::wall_us_from_igtl_time(m.header.timestamp) > t_kill_wall + 500000) ++after_kill;
  EXPECT_GE(after_kill, 60u) << "the Slicer-like client stopped receiving after another client was killed";
  std::printf("[ hil ] igtl: %zu TRANSFORMs checked against ground truth, %zu after the kill, %zu without an LCM match\n",
              check.checked, after_kill, check.unmatched);

  // Packaged ReceiveClient: every TRANSFORM printed its matrix (printed only when the CRC is good).
  EXPECT_GT(killed_lines_before, 0u) << read_file(killed_log);
  for (std::size_t i = 1; i < receivers.size(); ++i) {
    const std::string log = read_file(receivers[i]->log_path());
    EXPECT_EQ(log.find("Cannot connect"), std::string::npos) << log.substr(0, 2000);
    const std::size_t transforms = count_of(log, "Receiving TRANSFORM data type.");
    EXPECT_GE(transforms, 300u) << "ReceiveClient " << i << ":\n" << log.substr(0, 2000);
    EXPECT_GE(count_of(log, "Time stamp: 17"), transforms) << "timestamps are not UTC seconds";
    // ReceiveClient prints the matrix only when the body's CRC checks (the last one may be cut by SIGTERM).
    EXPECT_GE(count_of(log, "0, 0, 0, 1\n=============") + 1, transforms) << "TRANSFORMs whose CRC failed in ReceiveClient " << i;
  }
  // Packaged TrackingDataClient: STT_TDATA answered with TDATA of both tools.
  const std::string tlog = read_file(tracking.log_path());
  // It sends STP_TDATA after its first ten messages of any type: TDATA comes before that,
  // and at most what was already in flight after it.
  const auto stop_at = tlog.find("Sending STP_TDATA");
  ASSERT_NE(stop_at, std::string::npos) << tlog.substr(0, 3000);
  EXPECT_GE(count_of(tlog.substr(0, stop_at), "Receiving TDATA data type."), 1u) << tlog.substr(0, 3000);
  EXPECT_GE(count_of(tlog.substr(0, stop_at), " Name       : PointerToTracker"), 1u) << tlog.substr(0, 3000);
  EXPECT_GE(count_of(tlog.substr(0, stop_at), " Name       : ReferenceToTracker"), 1u) << tlog.substr(0, 3000);
  EXPECT_LE(count_of(tlog.substr(stop_at), "Receiving TDATA data type."), 2u) << "TDATA kept coming after STP_TDATA";

  // arnav-igtl: ten clients (the killed one was noticed alone, checked above; the others
  // may be dropped or closed when they are stopped).
  const auto stats = nlohmann::json::parse(read_file(dir + "/igtl_stats.json"));
  EXPECT_GE(stats["clients_accepted"].get<int>(), 10) << stats.dump();
  EXPECT_GE(stats["messages_skipped"].get<int>(), 1) << "the v2 STATUS was not read as a message";
  const std::string ilog = read_file(igtl.log_path());
  EXPECT_GE(count_of(ilog, " started tracking data"), 1u) << ilog;
  std::printf("[ hil ] igtl stats: %s\n", stats.dump().c_str());
  if (::testing::Test::HasFailure()) std::fprintf(stderr, "%s\n--- arnav-igtl ---\n%s\n", run.logs().c_str(), igtl.log_tail(6000).c_str());
}

// The appliance's synthetic camera publishing every frame (docs/camera.md): arnav-igtl turns
// them into IMAGE messages, checked by the packaged ReceiveClient (printed only with a good CRC).
TEST(HilIgtl, CameraFramesBecomeImagesForThePackagedClient) {
  HilRun run;
  HilRunOptions o;
  o.extra_config =
      "camera:\n  name: bench\n  source: synthetic\n  width: 640\n  height: 480\n  fps: 15\n"
      "  detector: {family: tag36h11, decimate: 2, threads: 1}\n"
      "  publish_frames: {every: 1, jpeg_quality: 80}\n"
      "  tools:\n    - name: cam_marker\n      tag: {id: 3, size_mm: 40}\n"
      "  synthetic:\n    boards:\n      - tool: cam_marker\n        trajectory: {distance_mm: 400, amplitude_mm: [30, 20, 40], period_s: 5}\n";
  const std::int64_t t0 = monotonic_us();
  ARNAV_BENCH_OR_SKIP(run.start(o));
  ASSERT_TRUE(run.wait_all_valid(10, t0, 90.0)) << "no tracking within 90 s\n" << run.logs();
  const std::string dir = run.dir();
  ChildProcess igtl({env_or("ARNAV_IGTL_EXE", ARNAV_IGTL_EXE), "--lcm", std::string(HilRun::kLcmUrl) + "&recv_buf_size=4194304", "--security", "off", "--port", "0",
                     "--image-downscale", "2", "--stats-json", dir + "/igtl_stats.json"},
                    {}, dir + "/igtl.log", true);
  const auto ready = igtl.read_line(30.0);
  ASSERT_TRUE(ready && ready->rfind("READY ", 0) == 0) << igtl.log_tail();
  const std::string port_text = ready->substr(6);
  ChildProcess receiver({env_or("ARNAV_IGTL_RECEIVE_CLIENT", ARNAV_IGTL_RECEIVE_CLIENT), "127.0.0.1", port_text}, {}, dir + "/receive_client.log");
  igtl::test::TestClient raw(std::stoi(port_text));
  ASSERT_TRUE(raw.connected()) << raw.why();
  std::size_t images = 0;
  igtl::test::Unpacked last_image;
  for (int i = 0; i < 100 && images < 10 && !raw.closed_by_server(); ++i) {
    raw.receive_until(1u << 20, 0.1);
    for (const auto& m : raw.take())
      if (m.header.type == "IMAGE") {
        ++images;
        last_image = igtl::test::unpack(m);
      }
  }
  receiver.stop(SIGTERM, 5.0);
  EXPECT_EQ(igtl.stop(SIGTERM, 15.0), 0) << igtl.log_tail();
  run.stop_appliance();
  run.stop_simulator();
  EXPECT_GE(images, 10u) << igtl.log_tail() << run.logs();
  EXPECT_TRUE(last_image.crc_ok);
  EXPECT_EQ(last_image.device_name, "Image_Reference");
  EXPECT_EQ(last_image.width, 320);
  EXPECT_EQ(last_image.height, 240);
  EXPECT_EQ(last_image.components, 3);
  EXPECT_GT(last_image.wall_us, wall_us() - 120'000'000);  // a UTC capture time, not zero
  if (const char* save = std::getenv("ARNAV_IGTL_SAVE_IMAGE"); save && last_image.crc_ok && last_image.components == 3) {
    // What a client received, as a picture (docs/igtl.md): RGB pixels back to BGR for OpenCV.
    cv::Mat rgb(last_image.height, last_image.width, CV_8UC3, last_image.pixels.data()), bgr;
    cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
    cv::imwrite(save, bgr);
  }
  const std::string log = read_file(receiver.log_path());
  EXPECT_GE(count_of(log, "Receiving IMAGE data type."), 3u) << log.substr(0, 2000);
  EXPECT_GE(count_of(log, "Dimensions            : (320, 240, 1)"), 3u) << "IMAGE printed only with a good CRC\n" << log.substr(0, 2000);
  std::printf("[ hil ] igtl: %zu IMAGEs to the raw client, %zu printed by ReceiveClient\n", images,
              count_of(log, "Dimensions            : (320, 240, 1)"));
}

}  // namespace
}  // namespace arnav::hil
