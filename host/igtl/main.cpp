// arnav-igtl: ARNav on OpenIGTLink, for 3D Slicer / SlicerIGT and PLUS users (docs/igtl.md).
//   arnav-igtl [--lcm URL] [--bind 127.0.0.1] [--port 18944] [--name TOOL=NAME] [--tip TOOL=X,Y,Z]
//              [--image-downscale N] [--image-rate-hz R] [--image-name NAME]
// Subscribes to ARNAV_POSE_.*, ARNAV_FRAME_.* and ARNAV_SURFACE_.* on the LCM bus (live, or a
// recorded session with --lcm 'file://LOG?speed=1') and serves TRANSFORM, TDATA, IMAGE, POLYDATA and STATUS
// to any number of OpenIGTLink clients. Prints "READY <port>" on stdout once listening.
#include <atomic>
#include <csignal>
#include <fstream>
#include <iostream>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>

#include <CLI/CLI.hpp>
#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>

#include "protocol/seal/sealed_lcm.hpp"
#include "host/igtl/bridge.hpp"
#include "protocol/channels.hpp"
#include "protocol/clock.hpp"
#include "protocol/guarded_main.hpp"

namespace {

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop.store(true); }

std::mutex g_log_mutex;
void log_line(const std::string& line) {
  std::lock_guard lock(g_log_mutex);
  std::cerr << "arnav-igtl: " << line << std::endl;
}

struct Handler {
  arnav::igtl::Bridge* bridge;
  void pose(const lcm::ReceiveBuffer*, const std::string&, const arnav::tool_pose_t* msg) { bridge->on_pose(*msg); }
  void frame(const lcm::ReceiveBuffer*, const std::string&, const arnav::image_frame_t* msg) { bridge->on_frame(*msg); }
  void surface(const lcm::ReceiveBuffer*, const std::string&, const arnav::surface_mesh_t* msg) { bridge->on_surface(*msg); }
};

// "TOOL=VALUE" -> (TOOL, VALUE); false when malformed.
bool split_assignment(const std::string& text, std::string& key, std::string& value) {
  const auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0 || eq + 1 == text.size()) return false;
  key = text.substr(0, eq);
  value = text.substr(eq + 1);
  return true;
}

// Exit 2 with a message naming the option on bad --name/--tip values.
int parse_tool_options(const std::vector<std::string>& names, const std::vector<std::string>& tips, arnav::igtl::BridgeOptions& out) {
  for (const auto& n : names) {
    std::string tool, device;
    if (!split_assignment(n, tool, device) || device.size() > arnav::igtl::kMaxDeviceNameChars) {
      std::cerr << "arnav-igtl: --name '" << n << "': expected TOOL=NAME with a NAME of at most 20 characters (e.g. pointer=StylusToReference)\n";
      return 2;
    }
    out.device_names[tool] = device;
  }
  for (const auto& t : tips) {
    std::string tool, xyz;
    double x = 0, y = 0, z = 0;
    char c1 = 0, c2 = 0;
    std::istringstream in;
    if (split_assignment(t, tool, xyz)) in.str(xyz);
    if (!(in >> x >> c1 >> y >> c2 >> z) || c1 != ',' || c2 != ',' || !in.eof()) {
      std::cerr << "arnav-igtl: --tip '" << t << "': expected TOOL=X,Y,Z, the pivot-calibrated tip in the tool frame in mm (e.g. pointer=0,0,-160.5)\n";
      return 2;
    }
    out.tips_Tool_mm[tool] = Eigen::Vector3d(x, y, z);
  }
  return 0;
}

nlohmann::json stats_json(const arnav::igtl::Bridge& bridge, const arnav::igtl::Server& server) {
  const auto& b = bridge.stats();
  const auto s = server.stats();
  return {{"poses", b.poses},
          {"transforms", b.transforms},
          {"not_seen", b.not_seen},
          {"unnamed", b.unnamed},
          {"tdata", b.tdata},
          {"frames", b.frames},
          {"images", b.images},
          {"frames_rate_limited", b.frames_rate_limited},
          {"frames_replaced", b.frames_replaced},
          {"frames_undecodable", b.frames_undecodable},
          {"surfaces", b.surfaces},
          {"polydata", b.polydata},
          {"surfaces_replaced", b.surfaces_replaced},
          {"surfaces_rejected", b.surfaces_rejected},
          {"polydata_pack_ms_mean", b.polydata > 0 ? b.polydata_pack_ms_total / static_cast<double>(b.polydata) : 0.0},
          {"polydata_pack_ms_max", b.polydata_pack_ms_max},
          {"clients_accepted", s.clients_accepted},
          {"clients_now", s.clients_now},
          {"clients_dropped", s.clients_dropped},
          {"clients_closed", s.clients_closed},
          {"messages_sent", s.messages_sent},
          {"messages_replaced", s.messages_replaced},
          {"keepalives_sent", s.keepalives_sent},
          {"requests_handled", s.requests_handled},
          {"polydata_unknown", s.polydata_unknown},
          {"messages_skipped", s.messages_skipped}};
}

int run(int argc, char** argv) {
  CLI::App app{"arnav-igtl: ARNav poses, video, surfaces and status over OpenIGTLink (docs/igtl.md)"};
  std::string lcm_url = "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304";
  arnav::igtl::ServerOptions server_options;
  arnav::igtl::BridgeOptions bridge_options;
  std::vector<std::string> names, tips;
  bool exit_at_end = false;
  std::string stats_path, key_file, security;
  app.add_option("--key", key_file, "the sealed bus's key (arnav-keygen; docs/protocol.md \"Sealed bus\"), also for a sealed log");
  app.add_option("--security", security, "'off': read a bus or log that is not sealed (bench, old logs)");
  app.add_option("--lcm", lcm_url, "LCM URL: the live bus (default: the appliance's, TTL 0) or a recorded session, file://LOG?speed=1");
  app.add_option("--bind", server_options.bind_address, "IPv4 address to listen on (default 127.0.0.1; 0.0.0.0 for every interface)");
  app.add_option("--port", server_options.port, "TCP port (default 18944, OpenIGTLink's; 0: any free port)")->check(CLI::Range(0, 65535));
  app.add_option("--name", names, "TOOL=NAME: the TRANSFORM name of a tool instead of the PLUS name <Tool>To<Parent> (<= 20 characters)");
  app.add_option("--tip", tips, "TOOL=X,Y,Z: also send <Tool>TipTo<Parent> with this pivot-calibrated tip (tool frame, mm)");
  app.add_option("--image-name", bridge_options.image_device_name, "IMAGE device name (default Image_Reference)");
  app.add_option("--image-downscale", bridge_options.image_downscale, "divide the camera image width and height by N (default 1)")
      ->check(CLI::Range(1, 16));
  app.add_option("--image-rate-hz", bridge_options.image_rate_hz, "at most this many IMAGE messages per second (default 0: every frame)")
      ->check(CLI::Range(0.0, 1000.0));
  app.add_option("--keepalive-s", server_options.keepalive_s, "STATUS_OK to a client after this long without a message (default 0.25)")
      ->check(CLI::Range(0.01, 60.0));
  app.add_option("--send-timeout-s", server_options.send_timeout_s, "drop a client whose send does not finish in this time (default 2)")
      ->check(CLI::Range(0.01, 600.0));
  app.add_flag("--exit-at-end", exit_at_end, "with a file:// log: exit when it ends (default: keep serving until SIGINT/SIGTERM)");
  app.add_option("--stats-json", stats_path, "write counters (poses, transforms, clients dropped, ...) here at exit");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  if (const int rc = parse_tool_options(names, tips, bridge_options); rc != 0) return rc;

  arnav::seal::BusSecurity bus_security;
  try {
    bus_security = arnav::seal::security_from_cli(key_file, security, "arnav-igtl");
  } catch (const arnav::seal::SecurityError& e) {
    std::cerr << e.what() << "\n";
    return 2;
  }
  log_line(bus_security.describe());
  arnav::seal::SealedLcm bus(lcm_url, bus_security);
  if (!bus.good()) {
    std::cerr << "arnav-igtl: --lcm '" << lcm_url
              << "': cannot open LCM there (udpm needs a multicast route, e.g. 224.0.0.0/4 on the interface; a file:// log must exist)\n";
    return 2;
  }
  std::optional<arnav::igtl::Server> server;
  try {
    server.emplace(server_options, log_line);
  } catch (const arnav::igtl::ServerError& e) {
    std::cerr << "arnav-igtl: " << e.what() << "\n";
    return 2;
  }
  arnav::igtl::Bridge bridge(bridge_options, *server, log_line);
  Handler handler{&bridge};
  bus.subscribe(std::string(arnav::channels::kPoseRegex), &Handler::pose, &handler);
  bus.subscribe(std::string(arnav::channels::kFramePrefix) + ".*", &Handler::frame, &handler);
  bus.subscribe(std::string(arnav::channels::kSurfacePrefix) + ".*", &Handler::surface, &handler);

  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  std::cout << "READY " << server->port() << std::endl;
  log_line("serving OpenIGTLink on " + server_options.bind_address + ":" + std::to_string(server->port()) + ", LCM " + lcm_url);
  const bool from_log = lcm_url.rfind("file://", 0) == 0;
  bool log_ended = false;
  while (!g_stop.load()) {
    if (log_ended) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      continue;
    }
    if (bus.handleTimeout(100) < 0) {
      if (g_stop.load()) break;  // interrupted by SIGINT/SIGTERM
      if (!from_log) {
        log_line("LCM receive failed: stopping");
        break;
      }
      bridge.flush();
      log_ended = true;
      log_line("end of the log: " + std::to_string(bridge.stats().poses) + " poses" + (exit_at_end ? "" : "; still serving until SIGINT/SIGTERM"));
      if (exit_at_end) break;
    }
  }
  server->stop();
  const auto j = stats_json(bridge, *server);
  log_line("stopped: " + j.dump());
  if (!stats_path.empty()) {
    std::ofstream out(stats_path);
    out << j.dump(2) << "\n";
    if (!out) {
      std::cerr << "arnav-igtl: --stats-json '" << stats_path << "': cannot write there\n";
      return 2;
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-igtl", [&] { return run(argc, argv); });
}
