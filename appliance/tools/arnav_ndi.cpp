// arnav-ndi: technicians' tool for the NDI Polaris (serial) and Vega/Lyra (Ethernet:
// PORT tcp:HOST[:PORT]).
//   ports                       list serial ports (USB VID:PID, description)
//   probe PORT                  firmware, serial number, port handles
//   track PORT --tool ROM...    print poses
//   decode FILE                 raw reply bytes -> one JSON object per reply
//   record PORT --tool ROM... --out FILE   session transcript (docs/appliance.md)
#include <CLI/CLI.hpp>

#include <csignal>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <iterator>
#include <thread>

#include <sys/stat.h>

#include "appliance/ndi/command.hpp"
#include "appliance/serial/posix_transport.hpp"
#include "appliance/ndi/recording_transport.hpp"
#include "appliance/serial/serial_transport.hpp"
#include "appliance/ndi/session.hpp"
#include "appliance/ndi/tcp_transport.hpp"
#include "appliance/tools/decode.hpp"
#include "protocol/clock.hpp"
#include "protocol/guarded_main.hpp"

namespace {

using namespace arnav;
volatile std::sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// tcp:HOST[:PORT] for Ethernet trackers; libserialport for ports it knows; termios for
// other tty devices (e.g. a pty).
ndi::TransportFactory port_factory(const std::string& port) {
  if (port.rfind("tcp:", 0) == 0) {
    const auto tcp = ndi::parse_tcp_address(port);
    if (!tcp) throw UsageError("'" + port + "' is not tcp:HOST or tcp:HOST:PORT (e.g. tcp:P9-B0103.local or tcp:192.168.1.50:8765)");
    return [o = *tcp] { return std::unique_ptr<ndi::Transport>(new ndi::TcpTransport(o)); };
  }
  bool known = false;
  try {
    known = ndi::port_exists(port);
  } catch (...) {
  }
  if (known) return [port] { return std::unique_ptr<ndi::Transport>(new ndi::SerialTransport(port)); };
  struct stat st {};
  if (::stat(port.c_str(), &st) == 0 && S_ISCHR(st.st_mode))
    return [port] { return std::unique_ptr<ndi::Transport>(new ndi::PosixTransport(port)); };
  std::string ports;
  try {
    ports = ndi::describe_ports(ndi::list_ports());
  } catch (const std::exception& e) {
    ports = std::string("  (cannot list ports: ") + e.what() + ")\n";
  }
  throw UsageError("no serial port '" + port + "'. Ports on this machine:\n" + ports);
}

void print_event(const ndi::Event& e) {
  if (e.severity != ndi::Severity::Info) std::cerr << "arnav-ndi: " << e.code << ": " << e.text << "\n";
}

ndi::SessionConfig session_config(const std::vector<std::string>& roms, int baud) {
  ndi::SessionConfig c;
  c.target_baud = baud;
  for (const auto& r : roms) c.tools.push_back({std::filesystem::path(r).stem().string(), r});
  return c;
}

int cmd_ports() {
  std::cout << ndi::describe_ports(ndi::list_ports());
  return 0;
}

int cmd_probe(const std::string& port, int baud) {
  ndi::Session s(session_config({}, baud), port_factory(port), print_event);
  ndi::ProbeResult r;
  if (!s.probe(r)) {
    std::cerr << "arnav-ndi: probe of " << port << " failed: " << s.detail() << "\n";
    return 1;
  }
  std::cout << "port:          " << port << "\n"
            << (port.rfind("tcp:", 0) == 0 ? std::string("link:          TCP (no baud rate)") : "baud:          " + std::to_string(r.baud))
            << "\nfirmware:      " << r.firmware
            << "\nserial number: " << r.serial_number << "\nversion text:\n";
  for (const auto& l : r.version_lines) std::cout << "  " << l << "\n";
  std::cout << "port handles:  " << r.handles.size() << "\n";
  for (const auto& h : r.handles) {
    char status[8];
    std::snprintf(status, sizeof status, "%03X", h.status);
    std::cout << "  handle " << ndi::hex2(h.handle) << " status " << status;
    if (h.has_info)
      std::cout << " type " << h.info.tool_type << " manufacturer " << h.info.manufacturer << " serial "
                << h.info.serial_number;
    std::cout << "\n";
  }
  return 0;
}

double g_rate_hz = 60.0;  // device frame rate: polls are paced to it

int run_tracking(ndi::Session& s, long frames) {
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  if (!s.start()) {
    std::cerr << "arnav-ndi: cannot start tracking: " << s.detail() << "\n";
    s.stop();
    return 1;
  }
  ndi::TrackingReply reply;
  long printed = 0;
  while (!g_stop && (frames <= 0 || printed < frames)) {
    if (s.state() != ndi::LinkState::Tracking) {
      if (!s.start()) std::this_thread::sleep_for(std::chrono::seconds(1));
      continue;
    }
    std::int64_t rx = 0;
    const ndi::PollResult result = s.poll(reply, rx);
    if (result == ndi::PollResult::SameFrame) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    if (result != ndi::PollResult::NewFrame) continue;
    // As the appliance does: the next frame is due one period after this one (a stream
    // is paced by the device).
    const auto next = std::chrono::microseconds(rx + static_cast<std::int64_t>(0.9e6 / g_rate_hz) - arnav::monotonic_us());
    if (!s.streaming() && next.count() > 0) std::this_thread::sleep_for(next);
    for (const auto& tool : s.tools()) {
      const ndi::HandleRecord* r = reply.find(tool.handle);
      std::printf("frame %u %-12s ", reply.frame_number(), tool.config.name.c_str());
      if (reply.has_device_time) std::printf("t_dev_s %.6f ", static_cast<double>(reply.device_time_ns) * 1e-9);
      if (!r) {
        std::printf("not reported\n");
      } else if (r->state == ndi::HandleState::Valid) {
        std::printf("p_mm %9.2f %9.2f %9.2f  q_wxyz %7.4f %7.4f %7.4f %7.4f  err_mm %.4f%s\n", r->p_NdiTool_mm[0],
                    r->p_NdiTool_mm[1], r->p_NdiTool_mm[2], r->q_NdiTool_wxyz[0], r->q_NdiTool_wxyz[1],
                    r->q_NdiTool_wxyz[2], r->q_NdiTool_wxyz[3], r->rms_error_mm,
                    r->out_of_volume() ? "  OUT OF VOLUME" : (r->partially_in_volume() ? "  PARTIALLY OUT" : ""));
      } else {
        std::printf("%s\n", r->state == ndi::HandleState::Missing ? "missing" : "disabled");
      }
    }
    std::fflush(stdout);
    ++printed;
  }
  s.stop();
  return 0;
}

int cmd_track(const std::string& port, const std::vector<std::string>& roms, int baud, long frames) {
  ndi::Session s(session_config(roms, baud), port_factory(port), print_event);
  return run_tracking(s, frames);
}

int cmd_record(const std::string& port, const std::vector<std::string>& roms, int baud, long frames,
               const std::string& out_path) {
  auto inner = port_factory(port);
  std::ofstream out(out_path);
  if (!out) throw UsageError("cannot write " + out_path);
  ndi::TransportFactory recording = [inner, &out] {
    return std::unique_ptr<ndi::Transport>(new ndi::RecordingTransport(inner(), out));
  };
  int rc = 0;
  {
    ndi::Session s(session_config(roms, baud), recording, print_event);
    rc = run_tracking(s, frames);
  }
  std::cerr << "arnav-ndi: transcript written to " << out_path << "\n";
  return rc;
}

int cmd_decode(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw UsageError("cannot read " + path);
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  for (const auto& j : tools::decode_replies(bytes)) std::cout << j.dump() << "\n";
  return 0;
}

}  // namespace

static int main_body(int argc, char** argv) {
  CLI::App cli{"arnav-ndi: NDI Polaris tool for technicians (docs/appliance.md)"};
  cli.require_subcommand(1);
  int baud = 115200;
  long frames = 0;
  std::string port, file, out_path;
  std::vector<std::string> roms;

  cli.add_subcommand("ports", "list serial ports with USB VID:PID and description");
  auto* probe = cli.add_subcommand("probe", "print firmware, serial number and port handles");
  probe->add_option("PORT", port, "serial port (or a pty path), or tcp:HOST[:PORT] for an Ethernet tracker")->required();
  probe->add_option("--baud", baud, "target baud rate")->capture_default_str();
  auto* track = cli.add_subcommand("track", "load tool ROMs and print poses until Ctrl-C");
  track->add_option("PORT", port, "serial port, or tcp:HOST[:PORT] for an Ethernet tracker")->required();
  track->add_option("--tool", roms, "tool definition (.rom), repeatable")->required()->check(CLI::ExistingFile);
  track->add_option("--baud", baud, "target baud rate")->capture_default_str();
  track->add_option("--frames", frames, "stop after this many frames (0: until Ctrl-C)");
  track->add_option("--rate", g_rate_hz, "device frame rate in Hz (polling pace)")->capture_default_str()->check(CLI::Range(1.0, 1000.0));
  auto* decode = cli.add_subcommand("decode", "decode raw reply bytes (as read from the wire) to JSON lines");
  decode->add_option("FILE", file, "file of raw bytes")->required()->check(CLI::ExistingFile);
  auto* record = cli.add_subcommand("record", "track and write a session transcript (docs/appliance.md)");
  record->add_option("PORT", port, "serial port, or tcp:HOST[:PORT] for an Ethernet tracker")->required();
  record->add_option("--tool", roms, "tool definition (.rom), repeatable")->required()->check(CLI::ExistingFile);
  record->add_option("--out", out_path, "transcript file to write")->required();
  record->add_option("--baud", baud, "target baud rate")->capture_default_str();
  record->add_option("--frames", frames, "stop after this many frames (0: until Ctrl-C)");
  record->add_option("--rate", g_rate_hz, "device frame rate in Hz (polling pace)")->capture_default_str()->check(CLI::Range(1.0, 1000.0));

  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = cli.exit(e);
    return rc == 0 ? 0 : 2;
  }
  try {
    if (!ndi::baud_code(baud)) throw UsageError("--baud " + std::to_string(baud) + " is not an NDI rate");
    if (cli.got_subcommand("ports")) return cmd_ports();
    if (cli.got_subcommand(probe)) return cmd_probe(port, baud);
    if (cli.got_subcommand(track)) return cmd_track(port, roms, baud, frames);
    if (cli.got_subcommand(decode)) return cmd_decode(file);
    if (cli.got_subcommand(record)) return cmd_record(port, roms, baud, frames, out_path);
  } catch (const UsageError& e) {
    std::cerr << "arnav-ndi: " << e.what() << "\n";
    return 2;
  } catch (const ndi::RomError& e) {
    std::cerr << "arnav-ndi: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "arnav-ndi: " << e.what() << "\n";
    return 1;
  }
  return 2;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-ndi", [&] { return main_body(argc, argv); });
}
