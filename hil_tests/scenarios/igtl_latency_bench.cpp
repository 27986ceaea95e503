// arnav-igtl-latency: LCM pose published -> OpenIGTLink TRANSFORM received by each client
// (docs/benchmarks.md). In private namespaces (LCM udpm on loopback only), it starts the
// real arnav-igtl, connects N clients on 127.0.0.1, publishes tool_pose_t for T tools at
// R Hz, and matches every TRANSFORM to its pose by name and timestamp (the pose's
// receive_time_wall_us, which the bench sets to a unique value). Optionally adds clients
// that connect and never read. Prints one JSON object.
//   arnav-igtl-latency [--rate-hz 60] [--tools 6] [--clients 4] [--seconds 20] [--stuck-clients 0]
#include <sys/socket.h>

#include <poll.h>

#include <algorithm>
#include <atomic>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <thread>

#include <CLI/CLI.hpp>
#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>

#include "arnav/tool_pose_t.hpp"
#include "hil_tests/bench/child_process.hpp"
#include "hil_tests/bench/namespaces.hpp"
#include "host/igtl/messages.hpp"
#include "host/igtl/test/test_client.hpp"
#include "protocol/channels.hpp"
#include "protocol/clock.hpp"
#include "protocol/guarded_main.hpp"
#include "protocol/pose_convert.hpp"

namespace {

constexpr const char* kLcmUrl = "udpm://239.255.76.67:7667?ttl=0";

struct Arrival {
  std::string name;
  std::int64_t wall_key_us;
  std::int64_t arrival_mono_us;
};

// Reads one client's stream until stop; records every TRANSFORM with its arrival time.
void receive_loop(int port, std::atomic<bool>& stop, std::vector<Arrival>& out, std::string& error) {
  arnav::igtl::test::TestClient client(port);
  if (!client.connected()) {
    error = client.why();
    return;
  }
  while (!stop.load()) {
    client.receive_until(1, 0.05);
    const std::int64_t now = arnav::monotonic_us();
    for (const auto& m : client.take())
      if (m.header.type == "TRANSFORM") out.push_back({m.header.device_name, arnav::igtl::wall_us_from_igtl_time(m.header.timestamp), now});
    if (client.closed_by_server()) {
      error = "server closed the connection";
      return;
    }
  }
}

// Baseline in the same run: a plain LCM subscriber of the same poses (LCM + scheduling alone).
struct LcmBaseline {
  std::vector<Arrival>* out;
  void on_pose(const lcm::ReceiveBuffer*, const std::string&, const arnav::tool_pose_t* p) {
    out->push_back({"T" + p->tool_name.substr(1) + "ToTracker", p->receive_time_wall_us, arnav::monotonic_us()});
  }
};

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const auto i = static_cast<std::size_t>(p / 100.0 * static_cast<double>(v.size() - 1) + 0.5);
  return v[std::min(i, v.size() - 1)];
}

std::string loadavg() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  in >> a >> b >> c;
  return a + " " + b + " " + c;
}

int run(int argc, char** argv) {
  CLI::App app{"arnav-igtl-latency: LCM pose -> OpenIGTLink TRANSFORM on the wire (docs/benchmarks.md)"};
  double rate_hz = 60.0, seconds = 20.0;
  int tools = 6, clients = 4, stuck = 0;
  app.add_option("--rate-hz", rate_hz, "tracker frames per second")->check(CLI::Range(1.0, 1000.0));
  app.add_option("--tools", tools, "tools per frame")->check(CLI::Range(1, 50));
  app.add_option("--clients", clients, "reading clients")->check(CLI::Range(1, 100));
  app.add_option("--stuck-clients", stuck, "extra clients that connect and never read")->check(CLI::Range(0, 100));
  app.add_option("--seconds", seconds, "publishing time")->check(CLI::Range(1.0, 3600.0));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  if (const std::string why = arnav::hil::enter_bench_namespaces(); !why.empty()) {
    std::cerr << "arnav-igtl-latency: cannot enter private namespaces (" << why << "): run as root\n";
    return 1;
  }
  const std::string dir = arnav::hil::make_temp_dir("arnav-igtl-latency");
  const char* exe_env = std::getenv("ARNAV_IGTL_EXE");
  arnav::hil::ChildProcess igtl({exe_env && *exe_env ? exe_env : ARNAV_IGTL_EXE, "--lcm", kLcmUrl, "--port", "0", "--stats-json", dir + "/stats.json"},
                                {}, dir + "/igtl.log", true);
  const auto ready = igtl.read_line(30.0);
  if (!ready || ready->rfind("READY ", 0) != 0) {
    std::cerr << "arnav-igtl-latency: arnav-igtl did not start:\n" << igtl.log_tail();
    return 1;
  }
  const int port = std::stoi(ready->substr(6));
  std::atomic<bool> stop{false};
  std::vector<std::vector<Arrival>> arrivals(static_cast<std::size_t>(clients));
  std::vector<std::string> errors(static_cast<std::size_t>(clients));
  std::vector<std::thread> threads;
  for (int c = 0; c < clients; ++c)
    threads.emplace_back([&, c] { receive_loop(port, stop, arrivals[static_cast<std::size_t>(c)], errors[static_cast<std::size_t>(c)]); });
  std::vector<std::unique_ptr<arnav::igtl::test::TestClient>> stuck_clients;
  for (int s = 0; s < stuck; ++s) stuck_clients.push_back(std::make_unique<arnav::igtl::test::TestClient>(port));
  std::vector<Arrival> baseline_arrivals;
  std::thread baseline_thread([&] {
    lcm::LCM sub(kLcmUrl);
    LcmBaseline handler{&baseline_arrivals};
    sub.subscribe(std::string(arnav::channels::kPoseRegex), &LcmBaseline::on_pose, &handler);
    while (!stop.load()) sub.handleTimeout(50);
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(500));  // clients connected

  lcm::LCM bus(kLcmUrl);
  if (!bus.good()) {
    std::cerr << "arnav-igtl-latency: cannot open LCM " << kLcmUrl << " in the private namespace\n";
    return 1;
  }
  const std::string load_before = loadavg();
  std::map<std::pair<std::string, std::int64_t>, std::int64_t> published;  // (device name, key) -> publish mono
  const auto period = std::chrono::duration<double>(1.0 / rate_hz);
  const auto start = std::chrono::steady_clock::now();
  const std::int64_t key0 = arnav::wall_us();
  const auto frames = static_cast<std::int64_t>(seconds * rate_hz);
  for (std::int64_t f = 0; f < frames; ++f) {
    std::this_thread::sleep_until(start + period * static_cast<double>(f));
    for (int t = 0; t < tools; ++t) {
      arnav::tool_pose_t p{};
      p.tool_name = "tool" + std::to_string(t);
      p.source = arnav::tool_pose_t::SOURCE_NDI;
      p.frame_parent = "Ndi";
      p.frame_child = "Tool";
      Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
      X.translation() = Eigen::Vector3d(static_cast<double>(f), t, -1500);
      arnav::set_pose(p, X);
      p.status = arnav::tool_pose_t::STATUS_VALID;
      p.device_frame_number = f;
      p.receive_time_wall_us = key0 + f * 1000 + t;  // unique per (frame, tool)
      p.sequence = f;
      const std::int64_t now = arnav::monotonic_us();
      p.publish_time_mono_us = now;
      published[{"Tool" + std::to_string(t) + "ToTracker", p.receive_time_wall_us}] = now;
      bus.publish(arnav::channels::pose(p.tool_name), &p);
    }
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(500));  // last messages arrive
  const std::string load_after = loadavg();
  stop.store(true);
  for (auto& t : threads) t.join();
  baseline_thread.join();
  stuck_clients.clear();
  igtl.stop(SIGTERM, 15.0);

  nlohmann::json j;
  std::vector<double> all_us;
  std::size_t unmatched = 0;
  for (int c = 0; c < clients; ++c) {
    std::vector<double> lat_us;
    for (const auto& a : arrivals[static_cast<std::size_t>(c)]) {
      const auto it = published.find({a.name, a.wall_key_us});
      if (it == published.end()) {
        ++unmatched;
        continue;
      }
      lat_us.push_back(static_cast<double>(a.arrival_mono_us - it->second));
    }
    all_us.insert(all_us.end(), lat_us.begin(), lat_us.end());
    j["clients"].push_back({{"received", lat_us.size()}, {"missed", published.size() - lat_us.size()}, {"p50_us", percentile(lat_us, 50)},
                            {"p99_us", percentile(lat_us, 99)}, {"max_us", percentile(lat_us, 100)}, {"error", errors[static_cast<std::size_t>(c)]}});
  }
  std::vector<double> baseline_us;
  for (const auto& a : baseline_arrivals)
    if (const auto it = published.find({a.name, a.wall_key_us}); it != published.end())
      baseline_us.push_back(static_cast<double>(a.arrival_mono_us - it->second));
  j["lcm_only_latency_us"] = {{"what", "the same poses received by a plain LCM subscriber in this process (LCM and scheduling alone)"},
                              {"samples", baseline_us.size()}, {"p50", percentile(baseline_us, 50)}, {"p99", percentile(baseline_us, 99)},
                              {"max", percentile(baseline_us, 100)}};
  std::ifstream stats_in(dir + "/stats.json");
  nlohmann::json server_stats = nlohmann::json::object();
  if (stats_in) server_stats = nlohmann::json::parse(stats_in, nullptr, false);
  j["what"] = "LCM tool_pose_t publish -> OpenIGTLink TRANSFORM received by a client on 127.0.0.1 (arnav-igtl process in between)";
  j["load"] = {{"rate_hz", rate_hz}, {"tools", tools}, {"clients", clients}, {"stuck_clients", stuck}, {"seconds", seconds},
               {"poses_published", published.size()}};
  j["latency_us"] = {{"samples", all_us.size()}, {"p50", percentile(all_us, 50)}, {"p90", percentile(all_us, 90)},
                     {"p99", percentile(all_us, 99)}, {"p999", percentile(all_us, 99.9)}, {"max", percentile(all_us, 100)}};
  j["unmatched"] = unmatched;
  j["machine"] = {{"loadavg_before", load_before}, {"loadavg_after", load_after}, {"cpus", std::thread::hardware_concurrency()}};
  j["arnav_igtl"] = server_stats;
  std::cout << j.dump(2) << std::endl;
  std::filesystem::remove_all(dir);
  return all_us.empty() ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-igtl-latency", [&] { return run(argc, argv); });
}
