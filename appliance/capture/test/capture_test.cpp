#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include <atomic>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include "appliance/capture/capture.hpp"
#include "appliance/capture/opencv_sources.hpp"
#include "appliance/capture/synthetic_source.hpp"
#include "protocol/clock.hpp"

namespace arnav::capture {
namespace {

std::filesystem::path fresh_dir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / ("arnav_capture_test_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

SyntheticSettings small_scene() {
  SyntheticSettings s;
  s.camera = markers::pinhole_camera(320, 240, 60.0);
  markers::TagBoard board = markers::single_tag_board("pointer", "tag36h11", 3, 40.0);
  camera_sim::Trajectory tr;
  tr.distance_mm = 300;
  tr.amplitude_mm = Eigen::Vector3d(20, 10, 20);
  s.boards.push_back({board, tr});
  return s;
}

struct EventLog {
  std::vector<CaptureEvent> events;
  Capture::EventSink sink() {
    return [this](const CaptureEvent& e) { events.push_back(e); };
  }
  int count(const std::string& code) const {
    int n = 0;
    for (const auto& e : events) n += e.code == code;
    return n;
  }
};

TEST(ImageFolderSource, ReadsInNameOrderAndSkipsUnreadableFilesByName) {
  const auto dir = fresh_dir("folder");
  for (int i = 0; i < 3; ++i) {
    cv::Mat img(48, 64, CV_8UC1, cv::Scalar(10 * i));
    cv::imwrite((dir / ("img_" + std::to_string(i) + ".png")).string(), img);
  }
  std::ofstream(dir / "img_1b.png") << "this is not a PNG";
  std::ofstream(dir / "notes.txt") << "ignored";
  EventLog log;
  Capture cap(std::make_unique<ImageFolderSource>(dir, 0.0, false), 0.1, log.sink());
  std::atomic<bool> stop{false};
  Frame f;
  std::vector<int> values;
  while (cap.next(f, stop) == Capture::Next::Frame) values.push_back(f.image.at<uint8_t>(0, 0));
  EXPECT_EQ(values, (std::vector<int>{0, 10, 20}));
  EXPECT_EQ(cap.stats().skipped, 1);
  ASSERT_EQ(log.count("CAMERA_IMAGE_SKIPPED"), 1);
  for (const auto& e : log.events) {
    if (e.code == "CAMERA_IMAGE_SKIPPED") {
      EXPECT_NE(e.text.find("img_1b.png"), std::string::npos) << e.text;
    }
  }
  EXPECT_EQ(log.count("CAMERA_END"), 1);
  // The skipped file still takes its place in the sequence: a gap there is a drop.
  EXPECT_EQ(cap.stats().dropped_frames, 1);
  std::filesystem::remove_all(dir);
}

TEST(ImageFolderSource, EmptyOrMissingFolderIsAnErrorNamingIt) {
  const auto dir = fresh_dir("empty");
  try {
    ImageFolderSource src(dir, 0.0, false);
    src.open();
    FAIL();
  } catch (const CaptureError& e) {
    EXPECT_NE(std::string(e.what()).find(dir.string()), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("no images"), std::string::npos);
  }
  ImageFolderSource missing(dir / "nope", 0.0, false);
  EXPECT_THROW(missing.open(), CaptureError);
  std::filesystem::remove_all(dir);
}

TEST(V4l2Source, MissingDeviceIsAnErrorNamingIt) {
  V4l2Settings s;
  s.device = "/dev/video_arnav_missing";
  V4l2Source src(s);
  try {
    src.open();
    FAIL();
  } catch (const CaptureError& e) {
    EXPECT_NE(std::string(e.what()).find("/dev/video_arnav_missing"), std::string::npos);
  }
}

TEST(VideoFileSource, ReadsAWrittenClipAndEnds) {
  const auto dir = fresh_dir("video");
  const auto path = dir / "clip.avi";
  {
    cv::VideoWriter writer(path.string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 25.0, cv::Size(64, 48), false);
    if (!writer.isOpened()) GTEST_SKIP() << "OpenCV has no MJPG/AVI writer on this machine";
    for (int i = 0; i < 5; ++i) writer.write(cv::Mat(48, 64, CV_8UC1, cv::Scalar(40 * i)));
  }
  VideoFileSource src(path, false, false);
  src.open();
  EXPECT_NEAR(src.nominal_fps(), 25.0, 0.01);
  Frame f;
  int n = 0;
  while (src.read(f).status == ReadStatus::Ok) {
    EXPECT_EQ(f.sequence, n);
    ++n;
  }
  EXPECT_EQ(n, 5);
  VideoFileSource missing(dir / "none.avi", false, false);
  EXPECT_THROW(missing.open(), CaptureError);
  std::filesystem::remove_all(dir);
}

TEST(SyntheticSource, WritesFramesAndGroundTruthBesideThem) {
  const auto dir = fresh_dir("synthetic");
  SyntheticSettings s = small_scene();
  s.realtime = false;
  s.frame_count = 4;
  s.frames_dir = dir;
  s.ground_truth_csv = dir / "ground_truth.csv";
  SyntheticSource src(s);
  src.open();
  Frame f;
  int n = 0;
  while (src.read(f).status == ReadStatus::Ok) {
    EXPECT_EQ(f.sequence, n);
    EXPECT_EQ(f.image.size(), cv::Size(320, 240));
    ++n;
  }
  EXPECT_EQ(n, 4);
  const auto rows = camera_sim::read_ground_truth(s.ground_truth_csv);
  ASSERT_EQ(rows.size(), 4u);
  for (const auto& r : rows) {
    EXPECT_EQ(r.board, "pointer");
    EXPECT_EQ(r.tags_visible, 1);
    EXPECT_TRUE(r.X_CamBoard.isApprox(src.X_CamBoard(0, r.sequence), 1e-6));
    EXPECT_TRUE(std::filesystem::exists(dir / r.frame_file)) << r.frame_file;
  }
  // The written frames replay through the folder source, in the same order.
  ImageFolderSource replay(dir, 0.0, false);
  replay.open();
  EXPECT_EQ(replay.files().size(), 4u);
  std::filesystem::remove_all(dir);
}

// Like a real camera: a frame is exposed at start + k / fps and delivered once its readout
// (here 5 ms) has ended; rendering is the bench's, done ahead on its own thread.
TEST(SyntheticSource, DeliversAfterTheReadoutWithTheExposureStamped) {
  SyntheticSettings s = small_scene();
  s.fps = 50.0;
  s.readout_s = 0.005;
  SyntheticSource src(s);
  src.open();
  Frame f;
  std::int64_t first_exposure = -1;
  for (int i = 0; i < 5; ++i) {
    ASSERT_EQ(src.read(f).status, ReadStatus::Ok);
    if (first_exposure < 0) first_exposure = f.capture_time_mono_us - f.sequence * 20'000;
    // The exposure is the frame's place on the camera's clock, whatever the delivery.
    EXPECT_EQ(f.capture_time_mono_us, first_exposure + f.sequence * 20'000);
    EXPECT_GE(f.delivered_time_mono_us, f.capture_time_mono_us + 5'000);
    EXPECT_GE(monotonic_us(), f.delivered_time_mono_us);
  }
  src.close();
  EXPECT_EQ(src.counters().delivered, 5);
}

// A static scene is rendered once and only re-exposed with each frame's noise: every frame
// is bit-identical to a full render of its scene with its seed (and differs from its
// neighbour by the noise alone); a moving scene is rendered anew.
TEST(SyntheticSource, StaticSceneReexposedBitIdenticalToAFullRender) {
  for (const bool moving : {false, true}) {
    SyntheticSettings s = small_scene();
    if (!moving) {
      s.boards[0].trajectory.amplitude_mm = Eigen::Vector3d::Zero();
      s.boards[0].trajectory.tilt_deg = 0.0;
      s.boards[0].trajectory.spin_deg = 0.0;
    }
    s.render.noise_sigma = 2.0;
    s.render.blur_sigma_px = 0.7;
    s.realtime = false;
    s.frame_count = 3;
    SyntheticSource src(s);
    src.open();
    camera_sim::SyntheticRenderer renderer(s.camera);
    Frame f;
    cv::Mat previous;
    while (src.read(f).status == ReadStatus::Ok) {
      camera_sim::RenderOptions opt = s.render;
      opt.noise_seed = s.render.noise_seed + static_cast<std::uint64_t>(f.sequence);
      const cv::Mat full = renderer.render({{&s.boards[0].board, src.X_CamBoard(0, f.sequence)}}, opt).image;
      EXPECT_EQ(cv::countNonZero(full != f.image), 0) << (moving ? "moving" : "static") << " frame " << f.sequence;
      if (!previous.empty()) {
        EXPECT_GT(cv::countNonZero(previous != f.image), 0) << "the noise differs per frame";
      }
      previous = f.image.clone();
    }
  }
}

// A reader that falls behind loses frames, and each one is counted with its cause (never a
// silent jump in the sequence): the timing file has every frame exactly once.
TEST(SyntheticSource, FramesNotTakenInTimeAreCountedAsDropped) {
  const auto dir = fresh_dir("timing");
  SyntheticSettings s = small_scene();
  s.fps = 100.0;
  s.timing_csv = dir / "timing.csv";
  SyntheticSource src(s);
  src.open();
  Frame f;
  ASSERT_EQ(src.read(f).status, ReadStatus::Ok);
  const std::int64_t first = f.sequence;
  std::this_thread::sleep_for(std::chrono::milliseconds(100));  // ten periods: the camera moves on
  ASSERT_EQ(src.read(f).status, ReadStatus::Ok);
  const std::int64_t second = f.sequence;
  src.close();
  ASSERT_GT(second, first + 1);
  const SyntheticCounters c = src.counters();
  EXPECT_EQ(c.delivered, 2);
  // (and maybe frames after the second that the renderer, ahead, could no longer make)
  EXPECT_GE(c.dropped_reader_late + c.dropped_render_late, second - first - 1);
  std::ifstream in(s.timing_csv);
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, kTimingCsvHeader);
  std::map<std::int64_t, std::string> status;
  while (std::getline(in, line)) {
    const auto comma = line.find(',');
    const std::int64_t seq = std::stoll(line.substr(0, comma));
    EXPECT_TRUE(status.emplace(seq, line.substr(line.rfind(',') + 1)).second) << "frame " << seq << " written twice";
  }
  for (std::int64_t k = first; k <= second; ++k) {
    ASSERT_TRUE(status.count(k)) << "frame " << k << " neither delivered nor counted as dropped";
    EXPECT_EQ(status[k] == "delivered", k == first || k == second) << k << ": " << status[k];
  }
  std::filesystem::remove_all(dir);
}

TEST(Capture, LostCameraIsReopenedAndReported) {
  SyntheticSettings s = small_scene();
  s.fps = 50.0;
  s.outage_at_s = 0.2;
  s.outage_duration_s = 0.3;
  EventLog log;
  Capture cap(std::make_unique<SyntheticSource>(s), 0.05, log.sink());
  std::atomic<bool> stop{false};
  Frame f;
  std::int64_t last_seq = -1;
  for (int i = 0; i < 45; ++i) {  // 0.9 s of frames at 50 Hz, across the outage
    ASSERT_EQ(cap.next(f, stop), Capture::Next::Frame);
    EXPECT_GT(f.sequence, last_seq);
    last_seq = f.sequence;
  }
  EXPECT_EQ(cap.stats().reconnects, 1);
  EXPECT_EQ(log.count("CAMERA_LOST"), 1);
  EXPECT_EQ(log.count("CAMERA_RECOVERED"), 1);
  // Reported once per outage, not per retry (zero if the machine stalled us past it).
  EXPECT_LE(log.count("CAMERA_OPEN_FAILED"), 1);
  // The frames of the outage are missing from the sequence and counted as dropped.
  EXPECT_GE(cap.stats().dropped_frames, 5);
  EXPECT_EQ(cap.stats().state, LinkState::Streaming);
}

// Unplugged for a while: the frames exposed meanwhile are absent, each with one timing row,
// and every other frame of the run has one too (delivered or dropped).
TEST(Capture, FramesOfAnOutageAreAbsentWithOneTimingRowEach) {
  const auto dir = fresh_dir("outage_timing");
  SyntheticSettings s = small_scene();
  s.fps = 50.0;
  s.outage_at_s = 0.2;
  s.outage_duration_s = 0.3;
  s.timing_csv = dir / "timing.csv";
  std::int64_t last_seq = -1;
  {
    Capture cap(std::make_unique<SyntheticSource>(s), 0.05, nullptr);
    std::atomic<bool> stop{false};
    Frame f;
    for (int i = 0; i < 40; ++i) {
      ASSERT_EQ(cap.next(f, stop), Capture::Next::Frame);
      last_seq = f.sequence;
    }
    ASSERT_EQ(cap.stats().reconnects, 1);
  }
  std::ifstream in(s.timing_csv);
  std::string line;
  std::getline(in, line);
  std::map<std::int64_t, std::string> status;
  while (std::getline(in, line)) {
    const std::int64_t seq = std::stoll(line.substr(0, line.find(',')));
    EXPECT_TRUE(status.emplace(seq, line.substr(line.rfind(',') + 1)).second) << "frame " << seq << " written twice";
  }
  int absent = 0;
  for (std::int64_t k = 0; k <= last_seq; ++k) {
    ASSERT_TRUE(status.count(k)) << "frame " << k << " has no timing row:\n" << [&] {
      std::ifstream again(s.timing_csv);
      std::stringstream all;
      all << again.rdbuf();
      return all.str();
    }();
    absent += status[k] == "absent";
  }
  EXPECT_GE(absent, 10);  // 0.3 s at 50 Hz (more when the machine stalls the reopen)
  std::filesystem::remove_all(dir);
}

TEST(Capture, SlowConsumerSeesDroppedFrames) {
  SyntheticSettings s = small_scene();
  s.fps = 100.0;
  Capture cap(std::make_unique<SyntheticSource>(s), 0.05, nullptr);
  std::atomic<bool> stop{false};
  Frame f;
  ASSERT_EQ(cap.next(f, stop), Capture::Next::Frame);
  for (int i = 0; i < 3; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(60));
    ASSERT_EQ(cap.next(f, stop), Capture::Next::Frame);
  }
  EXPECT_EQ(cap.stats().frames, 4);
  EXPECT_GE(cap.stats().dropped_frames, 9);  // >= 3 x (6 periods - 1 delivered - ...) under load
}

TEST(Capture, StopRequestEndsAWaitingCapture) {
  SyntheticSettings s = small_scene();
  s.outage_at_s = 0.0;
  s.outage_duration_s = 100.0;
  Capture cap(std::make_unique<SyntheticSource>(s), 0.05, nullptr);
  std::atomic<bool> stop{false};
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    stop = true;
  });
  Frame f;
  // The first open succeeds (outage measured from the first open), then reads are lost.
  Capture::Next n;
  do {
    n = cap.next(f, stop);
  } while (n == Capture::Next::Frame);
  EXPECT_EQ(n, Capture::Next::Stopped);
  stopper.join();
}

}  // namespace
}  // namespace arnav::capture
