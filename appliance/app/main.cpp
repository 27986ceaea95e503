// arnav-appliance: brings up the NDI Polaris named in the configuration and publishes
// tool poses (device rate), health (1 Hz) and events over LCM. SIGINT/SIGTERM: stop
// tracking, put the device back to 9600 baud, exit 0. Configuration errors: exit 2.
#include <CLI/CLI.hpp>
#include <lcm/lcm-cpp.hpp>

#include <csignal>
#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>
#include <thread>

#include <sys/stat.h>

#include "appliance/app/config.hpp"
#include "appliance/app/publisher.hpp"
#include "appliance/realtime/realtime.hpp"
#include "appliance/app/sim_process.hpp"
#include "appliance/app/swab.hpp"
#include "appliance/can/can_runtime.hpp"
#include "appliance/camera/camera_runtime.hpp"
#include "appliance/serial/posix_transport.hpp"
#include "appliance/serial/serial_transport.hpp"
#include "appliance/ndi/tcp_transport.hpp"
#include "protocol/seal/sealed_lcm.hpp"
#include "protocol/clock.hpp"
#include "protocol/guarded_main.hpp"
#include "protocol/seal/security_config.hpp"

namespace {

volatile std::sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

void install_signals() {
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;  // no SA_RESTART: blocking reads return early
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  std::signal(SIGPIPE, SIG_IGN);
}

bool is_char_device(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISCHR(st.st_mode);
}

const char* severity_name(arnav::ndi::Severity s) {
  switch (s) {
    case arnav::ndi::Severity::Info: return "info";
    case arnav::ndi::Severity::Warning: return "WARNING";
    case arnav::ndi::Severity::Error: return "ERROR";
  }
  return "?";
}

}  // namespace

static int main_body(int argc, char** argv) {
  using namespace arnav;
  CLI::App cli{"arnav-appliance: NDI Polaris -> LCM (poses, health, events). Configuration format: docs/appliance.md"};
  std::string config_path;
  bool check_only = false;
  bool print_health = false;
  cli.add_option("config", config_path, "YAML configuration file")->required();
  cli.add_flag("--check", check_only, "validate the configuration and exit (0 when valid)");
  cli.add_flag("--print-health", print_health, "also print each health message on stderr");
  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = cli.exit(e);
    return rc == 0 ? 0 : 2;
  }

  // The configuration's sections, each loaded by its component (file:line errors, exit 2):
  // NDI tools; the camera path (docs/camera.md, its own thread when the config has `camera:`);
  // the CAN path (docs/can.md, `can:`); the pointer swab (docs/register.md, `swab:`).
  app::AppConfig cfg;
  std::unique_ptr<camera::CameraRuntime> cam;
  std::unique_ptr<can::CanRuntime> can_bus;
  std::optional<app::SwabConfig> swab_config;
  auto config_error = [](const std::exception& e) {
    std::cerr << "arnav-appliance: configuration error: " << e.what() << "\n";
    return 2;
  };
  try {
    cfg = app::load_config(config_path);
    cam = camera::CameraRuntime::load(config_path);
    can_bus = can::CanRuntime::load(config_path);
    std::vector<std::string> tool_names, input_names;
    for (const auto& t : cfg.tools) tool_names.push_back(t.name);
    if (can_bus)
      for (const auto& i : can_bus->config().inputs) input_names.push_back(i.name);
    swab_config = app::load_swab_config(config_path, tool_names, input_names);
  } catch (const app::ConfigError& e) {
    return config_error(e);
  } catch (const camera::CameraConfigError& e) {
    return config_error(e);
  } catch (const can::CanConfigError& e) {
    return config_error(e);
  }
  // The sealed bus (docs/protocol.md, "Sealed bus"): a key file only its owner can read, or
  // `security: off` said in so many words; announced at start and on every health line.
  seal::BusSecurity security;
  // Each publishing thread (NDI, camera, CAN) seals as a sender of its own, a new one at
  // every start: said, so a report can check the host accepted only these (scripts/demo).
  seal::SealedLcm::announce_senders([](const std::string& sender) {
    std::cerr << "arnav-appliance: security: publishing as sender " << sender << std::endl;
  });
  auto resolve_security = [&]() -> bool {
    try {
      security = seal::resolve_security(cfg.security);
    } catch (const seal::SecurityError& e) {
      std::cerr << "arnav-appliance: configuration error: " << e.what() << "\n";
      return false;
    }
    if (!check_only) std::cerr << "arnav-appliance: " << security.describe() << "\n";
    return true;
  };
  auto start_camera = [&]() -> bool {
    if (!cam) return true;
    try {
      cam->start(cfg.lcm_url, security);
    } catch (const camera::CameraConfigError& e) {
      std::cerr << "arnav-appliance: configuration error: " << e.what() << "\n";
      return false;
    }
    std::cerr << "arnav-appliance: " << cam->summary() << "\n";
    return true;
  };
  auto start_can = [&]() -> bool {
    if (!can_bus) return true;
    try {
      can_bus->start(cfg.lcm_url, security, cfg.health_rate_hz);
    } catch (const can::CanConfigError& e) {
      std::cerr << "arnav-appliance: configuration error: " << e.what() << "\n";
      return false;
    }
    std::cerr << "arnav-appliance: " << can_bus->summary() << "\n";
    return true;
  };
  if (!cfg.ndi_enabled) {
    if (!resolve_security()) return 2;
    if (check_only) {
      std::cout << "configuration OK: " << (cam ? cam->summary() : std::string()) << (cam && can_bus ? "; " : "")
                << (can_bus ? can_bus->summary() : std::string()) << ", no NDI; " << security.describe() << "\n";
      return 0;
    }
    install_signals();
    if (!start_camera() || !start_can()) return 2;
    while (!g_stop && !(cam && cam->finished())) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    if (cam) cam->stop();
    if (can_bus) can_bus->stop();
    std::cerr << "arnav-appliance: stopping (" << (g_stop ? "signal" : "camera source ended") << ")\n";
    return 0;
  }

  // One reference frame for both paths (appliance/frames, docs/camera.md).
  std::shared_ptr<frames::ReferenceFrames> reference_frames;
  try {
    reference_frames = cam ? cam->frames() : camera::CameraRuntime::load_frames(config_path);
  } catch (const camera::CameraConfigError& e) {
    std::cerr << "arnav-appliance: configuration error: " << e.what() << "\n";
    return 2;
  }
  if (reference_frames->reference() == frames::Reference::Ref) {
    bool known = false;
    for (const auto& t : cfg.tools) known |= t.name == reference_frames->reference_tool();
    if (!known) {
      std::cerr << "arnav-appliance: configuration error: " << config_path << ": key 'frames.reference_tool': '"
                << reference_frames->reference_tool() << "' is not one of the NDI tools under 'tools:'\n";
      return 2;
    }
  }

  // Where the device is: a simulator on a pty, a libserialport port, or a tty device
  // libserialport does not list (a pty given by path).
  ndi::TransportFactory factory;
  std::string port_label = cfg.port;
  if (!cfg.ndi_host.empty()) {
    ndi::TcpOptions tcp;
    tcp.host = cfg.ndi_host;
    tcp.port = cfg.ndi_port;
    tcp.connect_timeout = std::chrono::milliseconds(cfg.connect_timeout_ms);
    factory = [tcp] { return std::unique_ptr<ndi::Transport>(new ndi::TcpTransport(tcp)); };
  } else if (cfg.port != "sim") {
    bool serial = false;
    try {
      serial = ndi::port_exists(cfg.port);
    } catch (...) {
    }
    if (serial) {
      factory = [port = cfg.port] { return std::unique_ptr<ndi::Transport>(new ndi::SerialTransport(port)); };
    } else if (is_char_device(cfg.port)) {
      factory = [port = cfg.port] { return std::unique_ptr<ndi::Transport>(new ndi::PosixTransport(port)); };
    } else {
      std::string ports;
      try {
        ports = ndi::describe_ports(ndi::list_ports());
      } catch (const std::exception& e) {
        ports = std::string("  (cannot list ports: ") + e.what() + ")\n";
      }
      std::cerr << "arnav-appliance: configuration error: " << cfg.source.string() << ":" << cfg.port_line << ": key 'port': no serial port '"
                << cfg.port << "'. Ports on this machine:\n"
                << ports << "Set 'port' to one of them, or to 'sim' for the bench simulator.\n";
      return 2;
    }
  }
  if (!resolve_security()) return 2;
  if (check_only) {
    std::cout << "configuration OK: " << cfg.tools.size() << " tool(s), port " << cfg.port
              << (cam ? "; " + cam->summary() : std::string()) << (can_bus ? "; " + can_bus->summary() : std::string())
              << (swab_config ? "; swab: tip of " + swab_config->tool + (swab_config->continuous ? " continuously" : " while " + swab_config->input + " is held") +
                                    " on " + swab_config->channel()
                              : std::string())
              << "; " << security.describe() << "\n";
    return 0;
  }

  seal::SealedLcm lcm(cfg.lcm_url, security);
  if (!lcm.good()) {
    std::cerr << "arnav-appliance: configuration error: " << cfg.source.string() << ": key 'lcm_url': cannot open LCM at '"
              << cfg.lcm_url << "'\n";
    return 2;
  }
  install_signals();

  std::unique_ptr<app::SimProcess> sim;
  if (cfg.port == "sim") {
    try {
      const std::string program = app::find_simulator(cfg.sim_command, std::filesystem::path("/proc/self/exe"));
      sim = std::make_unique<app::SimProcess>(program, cfg.sim_args);
    } catch (const app::SimError& e) {
      std::cerr << "arnav-appliance: " << e.what() << "\n";
      return 2;
    }
    port_label = sim->pty_path();
    std::cerr << "arnav-appliance: simulator ready on " << port_label << "\n";
    // Reopen through the link: after a simulated cable pull the simulator makes a new pty.
    std::error_code ec;
    const std::string path = std::filesystem::exists(sim->link_path(), ec) ? sim->link_path() : sim->pty_path();
    factory = [path] { return std::unique_ptr<ndi::Transport>(new ndi::PosixTransport(path)); };
  }

  app::Publisher publisher(lcm, cfg.tools, cfg.device_rate_hz);
  auto on_event = [&](const ndi::Event& e) {
    std::cerr << "arnav-appliance: [ndi] " << severity_name(e.severity) << " " << e.code << ": " << e.text << "\n";
    publisher.publish_event(e);
  };
  std::unique_ptr<ndi::Session> session;
  try {
    session = std::make_unique<ndi::Session>(cfg.session_config(), factory, on_event);
    session->set_cancel_flag(&g_stop);  // a signal during bring-up ends it at once
  } catch (const std::exception& e) {  // ROM or rate problems (already checked by the config)
    std::cerr << "arnav-appliance: configuration error: " << e.what() << "\n";
    return 2;
  }

  if (!start_camera()) return 2;
  std::unique_ptr<app::SwabSampler> swab;
  if (swab_config) {
    swab = std::make_unique<app::SwabSampler>(lcm, *swab_config);
    if (can_bus) can_bus->set_input_listener([s = swab.get()](const std::string& input, bool pressed) { s->set_input(input, pressed); });
    std::cerr << "arnav-appliance: swab: tip of " << swab_config->tool << (swab_config->continuous ? " continuously" : " while " + swab_config->input + " is held")
              << " on " << swab_config->channel() << "\n";
  }
  auto feed_swab = [&](const ndi::TrackingReply& r, std::int64_t receive_us) {
    if (!swab) return;
    for (const auto& t : session->tools()) {
      if (t.config.name != swab->config().tool) continue;
      const ndi::HandleRecord* rec = r.find(t.handle);
      const std::int64_t capture_wall_us = wall_us() - (monotonic_us() - receive_us);
      if (!rec || rec->state != ndi::HandleState::Valid) {
        swab->on_frame(std::nullopt, "", capture_wall_us);
        return;
      }
      const frames::Converted c = reference_frames->ndi_pose(ndi::X_NdiTool(*rec), receive_us);
      if (c.X_ParentChild) swab->on_frame(c.X_ParentChild, c.frame_parent, capture_wall_us);
      else swab->on_frame(ndi::X_NdiTool(*rec), "Ndi", capture_wall_us);  // as the tool poses: Ndi when the reference is not seen
    }
  };
  if (!start_can()) return 2;
  // NDI poses are published in the reference frame too; the reference tool's pose of
  // each frame is fed in before that frame's poses are published (one device frame).
  publisher.set_reference_frames(reference_frames);
  auto feed_reference = [&](const ndi::TrackingReply& r, std::int64_t receive_us) {
    if (reference_frames->reference() != frames::Reference::Ref) return;
    for (const auto& t : session->tools()) {
      if (t.config.name != reference_frames->reference_tool()) continue;
      const ndi::HandleRecord* rec = r.find(t.handle);
      if (rec && rec->state == ndi::HandleState::Valid) reference_frames->update_reference(ndi::X_NdiTool(*rec), receive_us);
      else reference_frames->reference_missing(receive_us);
    }
  };

  // Real-time settings for this (the polling) thread only: the camera thread and the
  // simulator were started above and keep normal scheduling.
  const app::CpuLatencyRequest cpu_latency(cfg.realtime.cpu_latency_us);
  if (!cpu_latency.error().empty())
    on_event({ndi::Severity::Warning, "APPLIANCE_REALTIME_DENIED", cpu_latency.error()});
  else if (cpu_latency.held())
    std::cerr << "arnav-appliance: CPU latency request " << cfg.realtime.cpu_latency_us << " us held\n";
  if (const std::string error = app::make_this_thread_realtime(cfg.realtime.priority); !error.empty())
    on_event({ndi::Severity::Warning, "APPLIANCE_REALTIME_DENIED", error});
  else if (cfg.realtime.priority > 0)
    std::cerr << "arnav-appliance: NDI polling thread SCHED_FIFO " << cfg.realtime.priority << "\n";

  const auto period_us = static_cast<std::int64_t>(1e6 / cfg.rate_hz);
  const auto health_period_us = static_cast<std::int64_t>(1e6 / cfg.health_rate_hz);
  std::int64_t next_health = monotonic_us() + health_period_us;
  std::int64_t window_start = monotonic_us();
  std::int64_t frames_in_window = 0;
  auto health_if_due = [&] {
    const std::int64_t now = monotonic_us();
    if (now < next_health) return;
    const double rate = static_cast<double>(frames_in_window) * 1e6 / static_cast<double>(std::max<std::int64_t>(1, now - window_start));
    const device_health_t h = publisher.publish_health(*session, port_label, rate);
    if (print_health) {
      std::fprintf(stderr,
                   "arnav-appliance: health %s %d baud %.1f Hz frames %lld crc %lld timeouts %lld resyncs %lld "
                   "garbage %lld errors %lld resets %lld reconnects %lld dropped %lld latency p50 %.1f p99 %.1f max %.1f us; %s\n",
                   std::string(ndi::to_string(session->state())).c_str(), h.baud, static_cast<double>(h.frame_rate_hz),
                   static_cast<long long>(h.frames_total), static_cast<long long>(h.crc_errors),
                   static_cast<long long>(h.timeouts), static_cast<long long>(h.resyncs),
                   static_cast<long long>(h.garbage_bytes), static_cast<long long>(h.error_replies),
                   static_cast<long long>(h.resets), static_cast<long long>(h.reconnects),
                   static_cast<long long>(h.dropped_frames), static_cast<double>(h.latency_p50_us),
                   static_cast<double>(h.latency_p99_us), static_cast<double>(h.latency_max_us), security.describe().c_str());
    }
    frames_in_window = 0;
    window_start = now;
    next_health = now + health_period_us;
  };
  // Bring-up and recovery take seconds: health keeps coming at its rate meanwhile.
  session->set_idle_callback(health_if_due);
  std::int64_t next_start_attempt = 0;
  // Reconnect backoff: 100 ms after the first failed bring-up, doubling to at most 2 s, so a
  // link that comes back is picked up at once and a dead one is not hammered.
  constexpr std::int64_t kFirstRetryUs = 100'000, kMaxRetryUs = 2'000'000;
  std::int64_t retry_us = kFirstRetryUs;
  std::int64_t next_poll = 0;
  ndi::TrackingReply reply;

  while (!g_stop) {
    std::int64_t now = monotonic_us();
    if (session->state() != ndi::LinkState::Tracking) {
      if (now >= next_start_attempt) {
        if (!session->start()) {
          next_start_attempt = monotonic_us() + retry_us;
          retry_us = std::min(kMaxRetryUs, retry_us * 2);
        } else {
          retry_us = kFirstRetryUs;
        }
        next_poll = monotonic_us();
      } else {
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      }
    } else {
      if (now < next_poll) std::this_thread::sleep_for(std::chrono::microseconds(next_poll - now));
      if (g_stop) break;
      std::int64_t receive_us = 0;
      switch (session->poll(reply, receive_us)) {
        case ndi::PollResult::NewFrame:
          feed_reference(reply, receive_us);
          publisher.publish_frame(*session, reply, receive_us);
          feed_swab(reply, receive_us);
          ++frames_in_window;
          // Next frame is due one device period after this one was read; poll a little
          // early and re-poll quickly if the device has no new frame yet.
          next_poll = session->streaming() ? monotonic_us() : receive_us + period_us * 9 / 10;  // a stream is not paced
          break;
        case ndi::PollResult::SameFrame:
          next_poll = monotonic_us() + (session->streaming() ? 0 : std::min<std::int64_t>(1000, period_us / 10));
          break;
        case ndi::PollResult::Failed: next_poll = monotonic_us(); break;
      }
    }
    health_if_due();
  }

  std::cerr << "arnav-appliance: stopping (signal)\n";
  if (cam) cam->stop();
  if (can_bus) can_bus->stop();
  if (swab) swab->flush();
  session->stop();
  publisher.publish_health(*session, port_label, 0.0);
  session.reset();
  sim.reset();
  return 0;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-appliance", [&] { return main_body(argc, argv); });
}
