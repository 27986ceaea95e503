// arnav-igtl-polydata-bench: the deforming organ as POLYDATA, whole pipeline (docs/benchmarks.md):
// in private namespaces (LCM udpm on loopback only) the real arnav-host runs a session on
// the scene (gravity on, no tool inputs: the model steps on the host clock and the organ
// sags), publishing its surfaces at --publish-rate-hz; the real arnav-igtl serves them to
// --clients reading clients on 127.0.0.1. Per client: Organ POLYDATA per second, new model
// steps per second (distinct time stamps: the organ as it deforms), distinct geometries,
// the age of what arrives (arrival - the model step's UTC time, which includes up to one
// publish period of waiting by design). From the programs' counters: the host's mesh build
// time, arnav-igtl's check + pack time per POLYDATA, the model's step rate. One JSON object.
//   arnav-igtl-polydata-bench [--scene FILE] [--publish-rate-hz 10] [--model-rate-hz 60] [--clients 4] [--seconds 20]
//   arnav-igtl-polydata-bench --pack-only 500   (no processes: arnav-igtl's check + pack of an organ-sized
//                                                 mesh, 4,902 vertices / 9,800 triangles, wall and thread CPU time)
#include <time.h>

#include <algorithm>
#include <atomic>
#include <csignal>
#include <fstream>
#include <iostream>
#include <set>
#include <thread>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "hil_tests/bench/namespaces.hpp"
#include "hil_tests/scenarios/surface_pipeline.hpp"
#include "host/igtl/bridge.hpp"
#include "host/igtl/messages.hpp"
#include "host/igtl/test/test_client.hpp"
#include "protocol/clock.hpp"
#include "protocol/guarded_main.hpp"

namespace {

struct Arrival {
  std::int64_t stamp_wall_us = 0;   // the model step's UTC time (POLYDATA header)
  std::int64_t arrival_wall_us = 0;
  std::size_t bytes = 0;
  std::uint64_t crc = 0;            // the body's CRC: equal bodies, equal geometry
};

struct MeshSize {
  std::size_t points = 0, polygons = 0;
};

void receive_loop(int port, std::atomic<bool>& stop, std::vector<Arrival>& out, std::string& error, MeshSize& size) {
  arnav::igtl::test::TestClient client(port);
  if (!client.connected()) {
    error = client.why();
    return;
  }
  while (!stop.load()) {
    client.receive_until(1, 0.05);
    const std::int64_t now = arnav::wall_us();
    for (const auto& m : client.take())
      if (m.header.type == "POLYDATA" && m.header.device_name == "Organ") {
        out.push_back({arnav::igtl::wall_us_from_igtl_time(m.header.timestamp), now, m.body.size() + arnav::igtl::kHeaderSize, m.header.crc});
        if (size.points == 0) {  // the first one read back with libopenigtlink (CRC checked)
          const auto u = arnav::igtl::test::unpack(m);
          if (!u.crc_ok) error = "an Organ POLYDATA failed its CRC";
          size = {u.points_mm.size(), u.polygons.size()};
        }
      }
    if (client.closed_by_server()) {
      error = "server closed the connection";
      return;
    }
  }
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(p / 100.0 * static_cast<double>(v.size() - 1) + 0.5))];
}

std::string loadavg() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  in >> a >> b >> c;
  return a + " " + b + " " + c;
}

double thread_cpu_ms() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
}

// arnav-igtl's part per mesh (Bridge::send_surface without the queueing): checks and packs
// an organ-sized sphere that deforms from one message to the next.
int pack_only(int n) {
  std::vector<double> wall_ms, cpu_ms;
  std::size_t bytes = 0, points = 0, triangles = 0;
  for (int i = 0; i < n; ++i) {
    const arnav::surface_mesh_t mesh = arnav::igtl::test::sphere_surface("organ", 50, 100, 0.05 * i, arnav::wall_us());
    points = mesh.positions_mm.size();
    triangles = mesh.triangles.size();
    std::string name, why;
    const double c0 = thread_cpu_ms();
    const auto t0 = std::chrono::steady_clock::now();
    const auto packet = arnav::igtl::polydata_from_surface(mesh, name, why);
    wall_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    cpu_ms.push_back(thread_cpu_ms() - c0);
    if (!packet) {
      std::cerr << "arnav-igtl-polydata-bench: " << why << "\n";
      return 1;
    }
    bytes = (*packet)->size();
  }
  const nlohmann::json out = {{"mode", "pack-only"}, {"messages", n}, {"points", points}, {"triangles", triangles}, {"bytes", bytes},
                              {"wall_ms_p50", percentile(wall_ms, 50)}, {"wall_ms_p99", percentile(wall_ms, 99)},
                              {"cpu_ms_p50", percentile(cpu_ms, 50)}, {"cpu_ms_p99", percentile(cpu_ms, 99)},
                              {"loadavg", loadavg()}};
  std::cout << out.dump(2) << std::endl;
  return 0;
}

nlohmann::json read_json(const std::filesystem::path& p) {
  std::ifstream in(p);
  nlohmann::json j;
  try {
    in >> j;
  } catch (const std::exception&) {
    j = nlohmann::json::object();
  }
  return j;
}

int run(int argc, char** argv) {
  CLI::App app{"arnav-igtl-polydata-bench: the deforming organ as OpenIGTLink POLYDATA, arnav-host -> LCM -> arnav-igtl (docs/benchmarks.md)"};
  arnav::hil::SurfacePipelineOptions o;
  o.scene_path = std::string(ARNAV_SOURCE_DIR) + "/hil_tests/scenarios/ar_demo/liver_navigation.scene.yaml";
  int clients = 4;
  double seconds = 20.0;
  app.add_option("--scene", o.scene_path, "scene file (default: the AR demo's liver, mass-spring model)");
  app.add_option("--publish-rate-hz", o.publish_rate_hz, "surfaces.publish_rate_hz")->check(CLI::Range(0.1, 1000.0));
  app.add_option("--model-rate-hz", o.model_rate_hz, "model.rate_hz")->check(CLI::Range(1.0, 1000.0));
  app.add_option("--clients", clients, "reading clients")->check(CLI::Range(1, 100));
  app.add_option("--seconds", seconds, "measuring time after the first Organ arrived")->check(CLI::Range(1.0, 3600.0));
  int pack_messages = 0;
  app.add_option("--pack-only", pack_messages, "only time arnav-igtl's check + pack of this many organ-sized meshes")->check(CLI::Range(1, 100000));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  if (pack_messages > 0) return pack_only(pack_messages);
  if (const std::string why = arnav::hil::enter_bench_namespaces(); !why.empty()) {
    std::cerr << "arnav-igtl-polydata-bench: cannot enter private namespaces (" << why << "): run as root\n";
    return 1;
  }
  const char* host_env = std::getenv("ARNAV_HOST_EXE");
  const char* igtl_env = std::getenv("ARNAV_IGTL_EXE");
  o.host_exe = host_env && *host_env ? host_env : ARNAV_HOST_EXE;
  o.igtl_exe = igtl_env && *igtl_env ? igtl_env : ARNAV_IGTL_EXE;
  arnav::hil::SurfacePipeline p;
  if (const std::string why = p.start(arnav::hil::make_temp_dir("arnav-igtl-polydata-bench"), o); !why.empty()) {
    std::cerr << "arnav-igtl-polydata-bench: " << why << "\n";
    return 1;
  }
  std::atomic<bool> stop{false};
  std::vector<std::vector<Arrival>> arrivals(static_cast<std::size_t>(clients));
  std::vector<std::string> errors(static_cast<std::size_t>(clients));
  std::vector<MeshSize> sizes(static_cast<std::size_t>(clients));
  std::vector<std::thread> threads;
  for (int c = 0; c < clients; ++c) {
    const auto i = static_cast<std::size_t>(c);
    threads.emplace_back([&, i] { receive_loop(p.port, stop, arrivals[i], errors[i], sizes[i]); });
  }
  const std::string load_before = loadavg();
  // Warm-up: until the first client has its first organ (the model built, the first round out).
  for (int i = 0; i < 600 && !stop.load(); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    if (!arrivals[0].empty()) break;  // read racily: only a start signal
  }
  const std::int64_t t_start = arnav::wall_us();
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  const std::int64_t t_end = arnav::wall_us();
  const std::string load_after = loadavg();
  stop = true;
  for (auto& t : threads) t.join();
  const int igtl_rc = p.igtl->stop(SIGTERM, 15.0);
  const int host_rc = p.host->stop(SIGTERM, 60.0);

  nlohmann::json per_client = nlohmann::json::array();
  std::vector<double> age_ms, rates, step_rates;
  std::size_t bytes = 0;
  for (std::size_t c = 0; c < arrivals.size(); ++c) {
    std::size_t n = 0;
    std::set<std::int64_t> steps;
    std::set<std::uint64_t> geometries;
    for (const auto& a : arrivals[c]) {
      if (a.arrival_wall_us < t_start || a.arrival_wall_us > t_end) continue;
      ++n;
      steps.insert(a.stamp_wall_us);
      geometries.insert(a.crc);
      age_ms.push_back(static_cast<double>(a.arrival_wall_us - a.stamp_wall_us) * 1e-3);
      bytes = a.bytes;
    }
    const double span_s = static_cast<double>(t_end - t_start) * 1e-6;
    rates.push_back(static_cast<double>(n) / span_s);
    step_rates.push_back(static_cast<double>(steps.size()) / span_s);
    per_client.push_back({{"organ_polydata", n}, {"organ_hz", rates.back()}, {"new_model_steps_hz", step_rates.back()},
                          {"distinct_geometries", geometries.size()}, {"error", errors[c]}});
  }
  const nlohmann::json host = read_json(p.dir / "host.json");
  const nlohmann::json igtl = read_json(p.dir / "igtl_stats.json");
  nlohmann::json out = {
      {"scene", o.scene_path},
      {"publish_rate_hz", o.publish_rate_hz},
      {"model_rate_hz_set", o.model_rate_hz},
      {"clients", clients},
      {"seconds", static_cast<double>(t_end - t_start) * 1e-6},
      {"organ_polydata_bytes", bytes},
      {"organ_points", sizes.empty() ? 0 : sizes[0].points},
      {"organ_triangles", sizes.empty() ? 0 : sizes[0].polygons},
      {"organ_hz_min", rates.empty() ? 0.0 : *std::min_element(rates.begin(), rates.end())},
      {"new_model_steps_hz_min", step_rates.empty() ? 0.0 : *std::min_element(step_rates.begin(), step_rates.end())},
      {"age_ms_p50", percentile(age_ms, 50)},
      {"age_ms_p99", percentile(age_ms, 99)},
      {"age_ms_max", percentile(age_ms, 100)},
      {"per_client", per_client},
      {"host_surfaces", host.value("surfaces", nlohmann::json::object())},
      {"host_model", host.contains("navigation") ? host["navigation"].value("model", nlohmann::json::object()) : nlohmann::json::object()},
      {"igtl_surfaces_received", igtl.value("surfaces", 0)},
      {"igtl_surfaces_replaced", igtl.value("surfaces_replaced", 0)},
      {"igtl_polydata", igtl.value("polydata", 0)},
      {"igtl_pack_ms_mean", igtl.value("polydata_pack_ms_mean", 0.0)},
      {"igtl_pack_ms_max", igtl.value("polydata_pack_ms_max", 0.0)},
      {"igtl_messages_replaced", igtl.value("messages_replaced", 0)},
      {"igtl_clients_dropped", igtl.value("clients_dropped", 0)},
      {"exit_codes", {{"arnav-igtl", igtl_rc}, {"arnav-host", host_rc}}},
      {"loadavg_before", load_before},
      {"loadavg_after", load_after},
      {"logs", p.dir.string()}};
  std::cout << out.dump(2) << std::endl;
  return igtl_rc == 0 && host_rc == 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-igtl-polydata-bench", [&] { return run(argc, argv); });
}
