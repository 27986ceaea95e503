// arnav-seal-bench: what sealing costs (docs/benchmarks.md, "Sealed bus").
//   arnav-seal-bench [--iterations N] [--json FILE]
// For a tool pose (an encoded tool_pose_t) and camera-frame sizes (1280x720 JPEG at
// quality 80 is 60-200 kB, docs/camera.md; a raw 1280x720 BGR frame as the upper bound):
//  - crypto: Sealer::seal and Opener::open per message (p50/p99/max, us);
//  - bus: publish + handle of one message through SealedLcm on LCM's in-process memq
//    provider, sealed minus off (the cost sealing adds to the appliance->host path, with
//    the copies it brings; no network);
//  - for frames: the share of one core sealing + opening takes at 60 Hz (mean x 60).
// Prints JSON on stdout (and to --json FILE).
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <iostream>
#include <random>

#include <time.h>

#include "arnav/image_frame_t.hpp"
#include "arnav/tool_pose_t.hpp"
#include "protocol/guarded_main.hpp"
#include "protocol/seal/sealed_lcm.hpp"

#include <sodium.h>

namespace {

using Clock = std::chrono::steady_clock;

struct Stats {
  std::vector<double> us;
  nlohmann::json json() {
    std::sort(us.begin(), us.end());
    double sum = 0;
    for (double v : us) sum += v;
    auto q = [&](double p) { return us[std::min(us.size() - 1, static_cast<std::size_t>(p * static_cast<double>(us.size())))]; };
    return {{"n", us.size()}, {"mean_us", sum / static_cast<double>(us.size())}, {"p50_us", q(0.5)}, {"p99_us", q(0.99)}, {"max_us", us.back()}};
  }
};

// CPU time of this thread (us): what the work costs the core, whatever else runs on the machine.
double thread_cpu_us() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e6 + static_cast<double>(ts.tv_nsec) * 1e-3;
}

double since_us(Clock::time_point t0) { return std::chrono::duration<double, std::micro>(Clock::now() - t0).count(); }

std::shared_ptr<const arnav::seal::SessionKey> bench_key() {
  std::array<std::uint8_t, arnav::seal::kKeyBytes> b{};
  std::mt19937 rng(7);
  for (auto& x : b) x = static_cast<std::uint8_t>(rng());
  return std::make_shared<const arnav::seal::SessionKey>(b);
}

std::int64_t wall_us() { return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch()).count(); }

nlohmann::json crypto(const std::vector<std::uint8_t>& plain, int n) {
  const auto key = bench_key();
  arnav::seal::Sealer sealer(key);
  arnav::seal::Opener opener(key);
  std::vector<std::uint8_t> env, out;
  Stats seal, open, both;
  double cpu0 = 0;
  for (int i = 0; i < n + 20; ++i) {
    if (i == 20) cpu0 = thread_cpu_us();
    const auto t0 = Clock::now();
    sealer.seal("ARNAV_FRAME_endoscope", plain, wall_us(), env);
    const double s = since_us(t0);
    const auto t1 = Clock::now();
    const auto v = opener.open("ARNAV_FRAME_endoscope", env, wall_us(), out);
    const double o = since_us(t1);
    if (v != arnav::seal::Verdict::Accepted || out.size() != plain.size()) throw std::runtime_error("bench: a sealed message did not open");
    if (i < 20) continue;  // warm-up: buffers reach their size
    seal.us.push_back(s);
    open.us.push_back(o);
    both.us.push_back(s + o);
  }
  const double cpu_per_message_us = (thread_cpu_us() - cpu0) / n;  // includes the two clock reads per message
  return {{"seal", seal.json()}, {"open", open.json()}, {"seal_plus_open", both.json()}, {"seal_plus_open_thread_cpu_mean_us", cpu_per_message_us}};
}

struct Counter {
  std::size_t got = 0;
  void on(const lcm::ReceiveBuffer*, const std::string&, const arnav::image_frame_t*) { ++got; }
  void on_pose(const lcm::ReceiveBuffer*, const std::string&, const arnav::tool_pose_t*) { ++got; }
};

template <class Msg>
Stats bus_round_trip(const Msg& msg, const std::string& channel, bool sealed, int n) {
  arnav::seal::BusSecurity sec;
  if (sealed) sec.key = bench_key();
  arnav::seal::SealedLcm bus("memq://", sec);
  Counter c;
  if constexpr (std::is_same_v<Msg, arnav::tool_pose_t>) bus.subscribe(channel, &Counter::on_pose, &c);
  else bus.subscribe(channel, &Counter::on, &c);
  Stats s;
  for (int i = 0; i < n + 20; ++i) {
    const auto t0 = Clock::now();
    bus.publish(channel, &msg);
    bus.handleTimeout(100);
    const double us = since_us(t0);
    if (i >= 20) s.us.push_back(us);
  }
  if (c.got != static_cast<std::size_t>(n + 20)) throw std::runtime_error("bench: messages lost on the memq bus");
  return s;
}

}  // namespace

static int main_body(int argc, char** argv) {
  CLI::App cli{"arnav-seal-bench: cost of sealing and opening bus messages (JSON)"};
  int iterations = 20000;
  std::string json_path;
  cli.add_option("--iterations", iterations, "messages per size (frames: a tenth, at least 200)")->check(CLI::Range(100, 10000000));
  cli.add_option("--json", json_path, "also write the JSON here");
  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return cli.exit(e) == 0 ? 0 : 2;
  }
  std::mt19937 rng(1);
  nlohmann::json out;
  out["cipher"] = "XChaCha20-Poly1305 (libsodium " + std::string(sodium_version_string()) + ")";
  out["envelope_overhead_bytes"] = arnav::seal::kOverheadBytes;

  arnav::tool_pose_t pose{};
  pose.tool_name = "scalpel";
  pose.frame_parent = "Ref";
  pose.frame_child = "Tool";
  pose.q_ParentChild_wxyz[0] = 1;
  std::vector<std::uint8_t> pose_bytes(static_cast<std::size_t>(pose.getEncodedSize()));
  pose.encode(pose_bytes.data(), 0, pose.getEncodedSize());
  nlohmann::json p = crypto(pose_bytes, iterations);
  p["bytes"] = pose_bytes.size();
  Stats plain = bus_round_trip(pose, "ARNAV_POSE_scalpel", false, iterations), sealed = bus_round_trip(pose, "ARNAV_POSE_scalpel", true, iterations);
  p["bus_memq_off"] = plain.json();
  p["bus_memq_sealed"] = sealed.json();
  out["pose"] = p;

  const int frames = std::max(200, iterations / 10);
  for (const auto& [name, bytes] : std::vector<std::pair<std::string, std::size_t>>{
           {"frame_jpeg_60kB", 60'000}, {"frame_jpeg_200kB", 200'000}, {"frame_raw_bgr_1280x720", 1280 * 720 * 3}}) {
    arnav::image_frame_t f{};
    f.camera_name = "endoscope";
    f.width = 1280;
    f.height = 720;
    f.size = static_cast<std::int32_t>(bytes);
    f.data.resize(bytes);
    for (auto& b : f.data) b = static_cast<std::uint8_t>(rng());
    std::vector<std::uint8_t> enc(static_cast<std::size_t>(f.getEncodedSize()));
    f.encode(enc.data(), 0, f.getEncodedSize());
    nlohmann::json j = crypto(enc, frames);
    j["bytes"] = enc.size();
    j["one_core_percent_at_60_hz"] = j["seal_plus_open_thread_cpu_mean_us"].get<double>() * 60.0 / 1e6 * 100.0;
    Stats off = bus_round_trip(f, "ARNAV_FRAME_endoscope", false, frames), on = bus_round_trip(f, "ARNAV_FRAME_endoscope", true, frames);
    j["bus_memq_off"] = off.json();
    j["bus_memq_sealed"] = on.json();
    out[name] = j;
  }
  std::cout << out.dump(2) << std::endl;
  if (!json_path.empty()) {
    std::ofstream f(json_path);
    f << out.dump(2) << "\n";
    if (!f) {
      std::cerr << "arnav-seal-bench: cannot write " << json_path << "\n";
      return 2;
    }
  }
  return 0;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-seal-bench", [&] { return main_body(argc, argv); });
}
