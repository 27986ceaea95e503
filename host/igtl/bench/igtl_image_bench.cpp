// arnav-igtl-image-bench: what one camera frame costs arnav-igtl (docs/benchmarks.md): a
// 1280x720 JPEG (quality 80, a textured synthetic scene) handed to Bridge::on_frame (the LCM
// thread's part: a copy into the image slot), then decoded, downscaled, BGR -> RGB, packed
// with its CRC and sent by the image thread to one reading client on 127.0.0.1. Frames are
// sent one at a time (the next after the client received the previous): frame handed over
// -> IMAGE received is the per-frame cost, its inverse the rate one image thread sustains.
//   arnav-igtl-image-bench [--frames 300] [--downscale 2] [--width 1280] [--height 720]
#include <algorithm>
#include <atomic>
#include <fstream>
#include <iostream>
#include <thread>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "host/igtl/bridge.hpp"
#include "host/igtl/test/test_client.hpp"
#include "protocol/clock.hpp"
#include "protocol/guarded_main.hpp"

namespace {

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(p / 100.0 * static_cast<double>(v.size() - 1) + 0.5))];
}

int run(int argc, char** argv) {
  CLI::App app{"arnav-igtl-image-bench: camera frame -> OpenIGTLink IMAGE cost (docs/benchmarks.md)"};
  int frames = 300, downscale = 2, width = 1280, height = 720;
  app.add_option("--frames", frames)->check(CLI::Range(10, 100000));
  app.add_option("--downscale", downscale)->check(CLI::Range(1, 16));
  app.add_option("--width", width)->check(CLI::Range(16, 8192));
  app.add_option("--height", height)->check(CLI::Range(16, 8192));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  cv::Mat scene(height, width, CV_8UC3);
  cv::randu(scene, cv::Scalar(0, 0, 0), cv::Scalar(60, 60, 60));
  for (int i = 0; i < 40; ++i)
    cv::circle(scene, {(i * 97) % width, (i * 53) % height}, 20 + (i * 7) % 80, cv::Scalar((i * 40) % 255, (i * 90) % 255, (i * 150) % 255), -1);
  std::vector<std::uint8_t> jpeg;
  cv::imencode(".jpg", scene, jpeg, {cv::IMWRITE_JPEG_QUALITY, 80});

  arnav::igtl::ServerOptions so;
  so.port = 0;
  arnav::igtl::Server server(so, [](const std::string&) {});
  arnav::igtl::BridgeOptions bo;
  bo.image_downscale = downscale;
  arnav::igtl::Bridge bridge(bo, server, [](const std::string& s) { std::cerr << s << "\n"; });
  std::atomic<bool> stop{false};
  std::atomic<std::size_t> images_received{0};
  arnav::igtl::test::TestClient client(server.port());
  std::thread reader([&] {
    while (!stop.load()) {
      client.receive_until(1, 0.05);
      for (const auto& m : client.take()) images_received += m.header.type == "IMAGE" ? 1 : 0;
    }
  });
  while (server.clients() < 1) std::this_thread::sleep_for(std::chrono::milliseconds(5));

  arnav::image_frame_t frame{};
  frame.camera_name = "bench";
  frame.width = frame.source_width = width;
  frame.height = frame.source_height = height;
  frame.channels = 3;
  frame.encoding = arnav::image_frame_t::ENCODING_JPEG;
  frame.size = static_cast<std::int32_t>(jpeg.size());
  frame.data = jpeg;
  std::vector<double> handover_ms, frame_ms;
  for (int i = 0; i < frames; ++i) {
    frame.sequence = i;
    frame.capture_time_mono_us = arnav::monotonic_us();
    frame.capture_time_wall_us = arnav::wall_us();
    const std::int64_t t0 = arnav::monotonic_us();
    bridge.on_frame(frame);
    handover_ms.push_back(static_cast<double>(arnav::monotonic_us() - t0) * 1e-3);
    while (images_received.load() < static_cast<std::size_t>(i + 1)) std::this_thread::sleep_for(std::chrono::microseconds(100));
    frame_ms.push_back(static_cast<double>(arnav::monotonic_us() - t0) * 1e-3);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  stop.store(true);
  reader.join();
  std::ifstream load_in("/proc/loadavg");
  std::string l1, l5, l15;
  load_in >> l1 >> l5 >> l15;
  const double p50 = percentile(frame_ms, 50);
  nlohmann::json j = {{"what", "image_frame_t (JPEG) handed to Bridge::on_frame -> IMAGE received by a client (decode, downscale, BGR->RGB, pack + CRC, send)"},
                      {"source", {{"width", width}, {"height", height}, {"jpeg_bytes", jpeg.size()}, {"jpeg_quality", 80}}},
                      {"downscale", downscale},
                      {"frames", frames},
                      {"image_bytes", (width / downscale) * (height / downscale) * 3},
                      {"lcm_thread_handover_ms", {{"p50", percentile(handover_ms, 50)}, {"p99", percentile(handover_ms, 99)}, {"max", percentile(handover_ms, 100)}}},
                      {"frame_to_image_received_ms", {{"p50", p50}, {"p99", percentile(frame_ms, 99)}, {"max", percentile(frame_ms, 100)}}},
                      {"sustained_fps_one_image_thread_at_p50", p50 > 0 ? 1000.0 / p50 : 0.0},
                      {"images_received_by_client", images_received.load()},
                      {"loadavg", l1 + " " + l5 + " " + l15},
                      {"cpus", std::thread::hardware_concurrency()}};
  std::cout << j.dump(2) << std::endl;
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-igtl-image-bench", [&] { return run(argc, argv); });
}
