// arnav-can: the technician's CAN tool (docs/can.md).
//   arnav-can listen IFACE|slcan:PORT [--config FILE]   frames (candump notation) and, with a
//                                                        configuration, inputs and devices
//   arnav-can record IFACE|slcan:PORT FILE               candump log (-l format)
//   arnav-can replay FILE IFACE|slcan:PORT               send a log with its timing
//   arnav-can decode FILE --config FILE                  a log through the decoder, offline
// Bad arguments, configurations, log lines and unavailable buses exit 2 with the reason.
#include <CLI/CLI.hpp>

#include <csignal>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <thread>

#include "appliance/can/can_runtime.hpp"
#include "appliance/can/candump_log.hpp"
#include "appliance/can/input_decoder.hpp"
#include "appliance/can/slcan.hpp"
#include "appliance/can/socketcan_transport.hpp"
#include "protocol/clock.hpp"
#include "protocol/guarded_main.hpp"

namespace {

using namespace arnav;
using namespace arnav::can;

volatile std::sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

struct Printer : DecoderSink {
  const CanConfig* cfg = nullptr;
  std::int64_t offset_us = 0;  // added to decoder times to print wall time
  std::ostream& out;
  explicit Printer(std::ostream& o) : out(o) {}
  std::string when(std::int64_t t) const {
    char b[40];
    const std::int64_t w = t + offset_us;
    std::snprintf(b, sizeof b, "(%lld.%06lld)", static_cast<long long>(w / 1'000'000), static_cast<long long>(w % 1'000'000));
    return b;
  }
  void on_input(const InputChange& c) override {
    const auto& in = cfg->inputs[c.input];
    out << when(c.decided_us) << " INPUT " << in.name << " " << (c.pressed ? "pressed" : "released");
    if (in.analog) out << " value " << c.value;
    switch (c.cause) {
      case InputChange::Cause::Frame: break;
      case InputChange::Cause::Debounce: out << " (after " << in.debounce_ms << " ms debounce)"; break;
      case InputChange::Cause::NodeLost: out << " (forced: device " << cfg->nodes[in.node].name << " lost)"; break;
      case InputChange::Cause::BusOff: out << " (forced: bus-off)"; break;
    }
    out << "\n";
  }
  void on_node(const NodeChange& c) override {
    out << when(c.time_us) << " DEVICE " << cfg->nodes[c.node].name << " " << to_string(c.state);
    if (c.state == NodeState::Lost) out << " (silent " << c.silent_us / 1000 << " ms)";
    if (c.canopen_state != 0xFF && c.state == NodeState::Alive) out << " (" << canopen_state_name(c.canopen_state) << ")";
    out << "\n";
  }
  void on_bus(const BusChange& c) override { out << when(c.time_us) << " BUS " << to_string(c.state) << "\n"; }
};

CanConfig bus_config(const std::string& target, int bitrate, int serial_baud, const std::optional<CanConfig>& from_file) {
  CanConfig c = from_file ? *from_file : CanConfig{};
  c.interface = target;
  c.slcan = target.rfind("slcan:", 0) == 0;
  c.port = c.slcan ? target.substr(6) : "";
  if (bitrate > 0) c.bitrate = bitrate;
  if (serial_baud > 0) c.serial_baud = serial_baud;
  if (!from_file) {
    c.nodes.clear();
    c.inputs.clear();
  }
  return c;
}

std::unique_ptr<CanTransport> open_or_explain(const CanConfig& c) {
  try {
    // listen/record want every frame: no filters, even with a configuration.
    CanConfig all = c;
    if (!all.slcan) return std::make_unique<SocketCanTransport>(all.interface, std::vector<std::pair<std::uint32_t, bool>>{});
    return open_transport(all);
  } catch (const CanUnavailable& e) {
    std::cerr << "arnav-can: " << e.what() << "\n";
    return nullptr;
  }
}

int listen_or_record(const CanConfig& c, bool decode, std::ostream& out, std::int64_t max_frames, double duration_s, bool log_format) {
  auto t = open_or_explain(c);
  if (!t) return 2;
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  std::optional<InputDecoder> decoder;
  Printer printer(std::cout);
  printer.cfg = &c;
  printer.offset_us = wall_us() - monotonic_us();
  if (decode) decoder.emplace(c);
  const std::int64_t end = duration_s > 0 ? monotonic_us() + static_cast<std::int64_t>(duration_s * 1e6) : INT64_MAX;
  std::int64_t n = 0;
  Received r;
  try {
    while (!g_stop && monotonic_us() < end && (max_frames <= 0 || n < max_frames)) {
      const std::int64_t wait = std::min<std::int64_t>(100'000, decoder ? decoder->next_deadline_us() - monotonic_us() : 100'000);
      if (t->receive(r, std::chrono::microseconds(std::max<std::int64_t>(0, wait)))) {
        ++n;
        const std::int64_t wall = r.device_wall_us >= 0 ? r.device_wall_us : r.receive_mono_us + printer.offset_us;
        if (log_format) out << format_log_line({wall, c.interface, r.frame}) << "\n";
        else out << format_log_line({wall, c.interface, r.frame}) << (r.frame.error ? "  ERRORFRAME" : "") << "\n";
        if (decoder) {
          decoder->tick(r.receive_mono_us, printer);
          decoder->on_frame(r.frame, r.receive_mono_us, printer);
        }
      }
      if (decoder) decoder->tick(monotonic_us(), printer);
    }
  } catch (const CanLinkLost& e) {
    std::cerr << "arnav-can: " << e.what() << "\n";
    return 1;
  }
  out.flush();
  const auto k = t->counters();
  std::cerr << "arnav-can: " << n << " frames (" << k.error_frames << " error frames";
  if (c.slcan) std::cerr << ", " << k.garbage_bytes << " garbage bytes, " << k.malformed << " bad lines";
  std::cerr << ")\n";
  return 0;
}

std::ifstream open_log(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw LogFileError(path + ": cannot read the log file");
  return in;
}

}  // namespace

static int main_body(int argc, char** argv) {
  CLI::App app{"arnav-can: listen to, record, replay and decode CAN traffic (SocketCAN or slcan). docs/can.md"};
  app.require_subcommand(1);
  std::string target, file, config_path;
  int bitrate = 0, serial_baud = 0;
  std::int64_t count = 0;
  double duration = 0, speed = 1.0;
  bool no_timing = false;
  auto add_bus = [&](CLI::App* s) {
    s->add_option("--bitrate", bitrate, "slcan: CAN bit rate (default: the configuration's, else 500000)");
    s->add_option("--serial-baud", serial_baud, "slcan: serial rate (default 115200)");
  };
  auto* listen = app.add_subcommand("listen", "print frames; with --config also inputs, devices and bus state");
  listen->add_option("bus", target, "can0, vcan0, ... or slcan:/dev/ttyUSB0")->required();
  listen->add_option("--config", config_path, "appliance configuration with a can: section");
  listen->add_option("--count", count, "stop after N frames");
  listen->add_option("--duration", duration, "stop after S seconds");
  add_bus(listen);
  auto* record = app.add_subcommand("record", "write frames as a candump log ((time) iface ID#DATA)");
  record->add_option("bus", target, "can0, vcan0, ... or slcan:/dev/ttyUSB0")->required();
  record->add_option("file", file, "log to write ('-': stdout)")->required();
  record->add_option("--count", count, "stop after N frames");
  record->add_option("--duration", duration, "stop after S seconds");
  add_bus(record);
  auto* replay = app.add_subcommand("replay", "send a candump log onto a bus with its timing");
  replay->add_option("file", file, "candump log")->required();
  replay->add_option("bus", target, "can0, vcan0, ... or slcan:/dev/ttyUSB0")->required();
  replay->add_flag("--no-timing", no_timing, "send as fast as possible");
  replay->add_option("--speed", speed, "time scale (2: twice as fast)")->check(CLI::Range(0.001, 1000.0));
  add_bus(replay);
  auto* decode = app.add_subcommand("decode", "run a candump log through the input decoder (no bus)");
  decode->add_option("file", file, "candump log")->required();
  decode->add_option("--config", config_path, "appliance configuration with a can: section")->required();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 2;
  }
  try {
    std::optional<CanConfig> cfg;
    if (!config_path.empty()) {
      cfg = load_can_config(config_path);
      if (!cfg) {
        std::cerr << "arnav-can: " << config_path << ": no can: section\n";
        return 2;
      }
    }
    if (bitrate > 0 && !slcan::bitrate_code(bitrate)) {
      std::cerr << "arnav-can: --bitrate " << bitrate << " is not an slcan rate\n";
      return 2;
    }
    if (*listen) return listen_or_record(bus_config(target, bitrate, serial_baud, cfg), cfg.has_value(), std::cout, count, duration, false);
    if (*record) {
      const CanConfig c = bus_config(target, bitrate, serial_baud, std::nullopt);
      if (file == "-") return listen_or_record(c, false, std::cout, count, duration, true);
      std::ofstream out(file);
      if (!out) {
        std::cerr << "arnav-can: cannot write " << file << "\n";
        return 2;
      }
      return listen_or_record(c, false, out, count, duration, true);
    }
    if (*decode) {
      std::ifstream in = open_log(file);
      LogReader reader(in, file);
      InputDecoder d(*cfg);
      Printer printer(std::cout);
      printer.cfg = &*cfg;
      std::int64_t n = 0;
      while (auto r = reader.next()) {
        d.tick(r->time_us, printer);
        d.on_frame(r->frame, r->time_us, printer);
        ++n;
      }
      std::cerr << "arnav-can: " << n << " frames, " << d.counters().presses << " presses, " << d.counters().releases << " releases\n";
      return 0;
    }
    // replay: read the whole log first, so a bad line is found before anything is sent.
    std::ifstream in = open_log(file);
    LogReader reader(in, file);
    std::vector<LogRecord> records;
    while (auto r = reader.next()) records.push_back(std::move(*r));
    auto t = open_or_explain(bus_config(target, bitrate, serial_baud, std::nullopt));
    if (!t) return 2;
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);
    const std::int64_t t0 = monotonic_us();
    std::int64_t sent = 0, skipped = 0;
    for (const auto& r : records) {
      if (g_stop) break;
      if (!no_timing) {
        const auto due = t0 + static_cast<std::int64_t>(static_cast<double>(r.time_us - records.front().time_us) / speed);
        const std::int64_t now = monotonic_us();
        if (due > now) std::this_thread::sleep_for(std::chrono::microseconds(due - now));
      }
      if (r.frame.error) {  // error frames are the controller's report; they cannot be sent
        ++skipped;
        continue;
      }
      t->send(r.frame);
      ++sent;
    }
    std::cerr << "arnav-can: " << sent << " frames sent to " << target << (skipped ? ", " + std::to_string(skipped) + " error frames skipped" : "") << "\n";
    return 0;
  } catch (const CanConfigError& e) {
    std::cerr << "arnav-can: configuration error: " << e.what() << "\n";
    return 2;
  } catch (const LogFileError& e) {
    std::cerr << "arnav-can: " << e.what() << "\n";
    return 2;
  } catch (const CanLinkLost& e) {
    std::cerr << "arnav-can: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "arnav-can: " << e.what() << "\n";
    return 1;
  }
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-can", [&] { return main_body(argc, argv); });
}
