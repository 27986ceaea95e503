// arnav-host: the navigation host.
//   arnav-host SESSION.yaml [--record DIR] [--replay LOG [--replay-speed X]] ...
// runs the navigation session the file declares (docs/overlay.md): poses, frames, health
// and events in over LCM (or from an lcm-logger log), the tissue model on its own thread,
// the AR overlay on every camera frame, recording. Without a session file (or with one
// that declares no camera) it is the status monitor: freshness per tool and a status
// table. --summary-json writes what it saw at exit (used by scripts/demo and the bench).
#include <atomic>
#include <chrono>
#include <csignal>
#include <fstream>
#include <iostream>
#include <thread>

#include <lcm/lcm_coretypes.h>

#include <CLI/CLI.hpp>
#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>

#include "host/app/bus_handlers.hpp"
#include "host/app/navigation_session.hpp"
#include "host/app/status_report.hpp"
#include "host/app/surface_publisher.hpp"
#include "host/mesh/load_error.hpp"
#include "host/scene/scene.hpp"
#include "host/overlay/egl_context.hpp"
#include "protocol/channels.hpp"
#include "protocol/clock.hpp"
#include "protocol/guarded_main.hpp"
#include "protocol/seal/log_opener.hpp"
#include "protocol/seal/sealed_lcm.hpp"

namespace {

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop.store(true); }

using Handler = arnav::host::StatusHandler<arnav::host::ToolFreshnessTracker>;

nlohmann::json summary(const arnav::host::ToolFreshnessTracker& tracker, double run_s) {
  nlohmann::json j;
  j["run_s"] = run_s;
  j["stale_after_ms"] = static_cast<double>(tracker.stale_after_us()) * 1e-3;
  for (const auto& [name, t] : tracker.tools()) {
    j["tools"][name] = {{"messages", t.messages},
                        {"valid", t.valid},
                        {"mean_valid_rate_hz", run_s > 0 ? static_cast<double>(t.valid) / run_s : 0.0},
                        {"duplicate_frames", t.duplicate_frames},
                        {"frame_gaps", t.frame_gaps},
                        {"counter_restarts", t.counter_restarts},
                        {"sequence_gaps", t.sequence_gaps},
                        {"stale_episodes", t.stale_episodes},
                        {"max_valid_gap_ms", static_cast<double>(t.max_valid_gap_us) * 1e-3},
                        {"stale_at_exit", t.stale}};
  }
  for (const auto& [device, h] : tracker.health()) {
    j["health"][device] = {{"link_state", h.link_state},   {"frame_rate_hz", h.frame_rate_hz}, {"frames_total", h.frames_total},
                           {"crc_errors", h.crc_errors},   {"timeouts", h.timeouts},           {"resyncs", h.resyncs},
                           {"garbage_bytes", h.garbage_bytes}, {"error_replies", h.error_replies}, {"resets", h.resets},
                           {"reconnects", h.reconnects},   {"dropped_frames", h.dropped_frames},
                           {"latency_p50_us", h.latency_p50_us}, {"latency_p99_us", h.latency_p99_us},
                           {"latency_max_us", h.latency_max_us}, {"detail", h.detail}};
  }
  j["events"] = nlohmann::json::array();
  for (const auto& e : tracker.events())
    j["events"].push_back({{"source", e.source}, {"severity", e.severity}, {"code", e.code}, {"text", e.text}, {"time_mono_us", e.time_mono_us}});
  return j;
}

// What the bus's receiver did with every message (docs/protocol.md, "Sealed bus").
nlohmann::json security_json(const arnav::seal::BusSecurity& security, const arnav::seal::OpenCounters& c, std::uint64_t sealed_without_key,
                             const std::vector<arnav::seal::SenderTally>* senders = nullptr) {
  nlohmann::json j = {{"mode", security.sealed() ? "sealed" : "off"}, {"accepted", c.accepted}, {"dropped", c.dropped()},
                      {"forged", c.forged},     {"tampered", c.tampered}, {"replayed", c.replayed}, {"stale", c.stale},
                      {"unsealed", c.unsealed}, {"malformed", c.malformed}, {"sealed_without_key", sealed_without_key}};
  if (security.sealed()) j["key_id"] = security.key->key_id_hex();
  // Live: every sender accepted from, audited apart from the replay window (docs/protocol.md).
  if (senders && security.sealed()) {
    j["senders"] = nlohmann::json::array();
    for (const auto& t : *senders)
      j["senders"].push_back({{"sender", t.sender}, {"accepted", t.accepted}, {"highest_counter", t.highest},
                              {"accepted_twice", t.accepted_twice}, {"audit_truncated", t.audit_truncated}});
  }
  return j;
}

// The session file's `security:`, with the key loaded; prints why not (exit 2) otherwise.
std::optional<arnav::seal::BusSecurity> session_security(const arnav::host::SessionConfig& config) {
  try {
    arnav::seal::BusSecurity s = arnav::seal::resolve_security(config.security);
    std::cout << "arnav-host: " << s.describe() << std::endl;
    return s;
  } catch (const arnav::seal::SecurityError& e) {
    std::cerr << "arnav-host: " << e.what() << "\n";
    return std::nullopt;
  }
}

struct Cli {
  std::string key_file, security;  // the status monitor's --key / --security off
  std::string session_path, record_dir, replay_log;
  double replay_speed = 1.0;
  std::string lcm_url = "udpm://239.255.76.67:7667?ttl=0";
  double stale_after_ms = 250.0, print_period_s = 1.0, duration_s = 0.0;
  std::string summary_path;
  bool quiet = false, events = false, print_summary = false;
};

int write_summary(const Cli& cli, const nlohmann::json& j) {
  if (cli.summary_path.empty()) return 0;
  std::ofstream out(cli.summary_path);
  out << j.dump(2) << "\n";
  if (!out) {
    std::cerr << "arnav-host: cannot write " << cli.summary_path << "\n";
    return 1;
  }
  return 0;
}

// Replays an lcm-logger log through the session on this thread (deterministic): the
// session clock is the log's receive time mapped onto the appliance's monotonic clock.
// Before each message is handed in, the model performs the steps due by its time (as the
// live model thread would have by then), so every step sees only the poses, pedal states
// and frames received before it. (Stepping only at camera frames ran a frame's ~4 steps
// after every pose up to that frame had arrived: each step used the grasper pose of up to
// a frame later, the grasp's target jumped once per frame, and a gap in the grasper's poses
// never looked stale. On the demo's ring cut under the grasper's pull that put the replay's
// cut-path tail at p95 9.3 / max 14.9 mm against the live 2.8 / 2.8; docs/benchmarks.md,
// "Fifth round".)
int run_replay(const Cli& cli, arnav::host::NavigationSession& session, const std::string& frame_channel,
               const arnav::seal::BusSecurity& security) {
  lcm::LogFile log(cli.replay_log, "r");
  if (!log.good()) {
    std::cerr << "arnav-host: --replay " << cli.replay_log << ": cannot open the log (an lcm-logger file)\n";
    return 2;
  }
  std::optional<std::int64_t> offset_us;  // appliance monotonic - wall
  std::int64_t first_ts = -1, last_now = 0, next_print = -1, undecodable = 0, messages = 0;
  const auto wall0 = std::chrono::steady_clock::now();
  const auto starts = [](const std::string& s, std::string_view p) { return s.compare(0, p.size(), p) == 0; };
  // The log holds the bus's sealed bytes: each event is opened with the key, and what the
  // live receiver would have dropped (forged, tampered, replayed, stale) is dropped here too.
  // Only the channels the live session subscribes to are opened (and counted), as live.
  arnav::seal::LogOpener opener(security);
  const auto reads = [&](const std::string& ch) {
    return starts(ch, arnav::channels::kPosePrefix) || starts(ch, arnav::channels::kHealthPrefix) || ch == arnav::channels::kEvents ||
           ch == arnav::channels::kInput || ch == arnav::channels::kInputState || (!session.swab_channel().empty() && ch == session.swab_channel()) ||
           (!frame_channel.empty() && ch == frame_channel);
  };
  // What the opener dropped goes to the session's security banner at the log's time (as
  // live at the receive time); drops before the first accepted message wait for the clock.
  struct Drop {
    arnav::seal::Verdict verdict;
    std::string channel;
    std::int64_t timestamp;
  };
  std::vector<Drop> early_drops;
  while (!g_stop.load()) {
    const lcm::LogEvent* raw_ev = log.readNextEvent();
    if (!raw_ev) break;
    ++messages;
    if (!reads(raw_ev->channel)) continue;
    const auto opened = opener.open(*raw_ev);
    if (!opened) {
      if (offset_us) session.on_bus_drop(opener.last_verdict(), raw_ev->channel, raw_ev->timestamp + *offset_us);
      else if (early_drops.size() < 100000) early_drops.push_back({opener.last_verdict(), raw_ev->channel, raw_ev->timestamp});
      continue;
    }
    lcm::LogEvent plain_ev = *raw_ev;
    plain_ev.data = const_cast<std::uint8_t*>(opened->data());
    plain_ev.datalen = static_cast<std::int32_t>(opened->size());
    const lcm::LogEvent* ev = &plain_ev;
    if (first_ts < 0) first_ts = ev->timestamp;
    if (cli.replay_speed > 0) {
      const auto due = wall0 + std::chrono::microseconds(static_cast<std::int64_t>(static_cast<double>(ev->timestamp - first_ts) / cli.replay_speed));
      std::this_thread::sleep_until(due);
    }
    const auto now = [&](std::int64_t mono, std::int64_t wall) {
      if (!offset_us) {
        offset_us = mono - wall;
        for (const Drop& d : early_drops) session.on_bus_drop(d.verdict, d.channel, d.timestamp + *offset_us);
        early_drops.clear();
      }
      last_now = ev->timestamp + *offset_us;
      return last_now;
    };
    const std::string& ch = ev->channel;
    if (starts(ch, arnav::channels::kPosePrefix)) {
      arnav::tool_pose_t m;
      if (m.decode(ev->data, 0, ev->datalen) < 0) { ++undecodable; continue; }
      const std::int64_t t = now(m.publish_time_mono_us, m.publish_time_wall_us);
      session.advance_model(t);
      session.on_pose(m, t);
    } else if (starts(ch, arnav::channels::kHealthPrefix)) {
      arnav::device_health_t m;
      if (m.decode(ev->data, 0, ev->datalen) < 0) { ++undecodable; continue; }
      const std::int64_t t = now(m.publish_time_mono_us, m.publish_time_wall_us);
      session.advance_model(t);
      session.on_health(m, t);
    } else if (ch == arnav::channels::kEvents) {
      arnav::appliance_event_t m;
      if (m.decode(ev->data, 0, ev->datalen) < 0) { ++undecodable; continue; }
      session.advance_model(now(m.time_mono_us, m.time_wall_us));
      session.on_event(m);
    } else if (ch == arnav::channels::kInput || ch == arnav::channels::kInputState) {
      arnav::input_event_t m;
      if (m.decode(ev->data, 0, ev->datalen) < 0) { ++undecodable; continue; }
      const std::int64_t t = now(m.publish_time_mono_us, m.publish_time_wall_us);
      session.advance_model(t);
      session.on_input(m, t);
    } else if (!session.swab_channel().empty() && ch == session.swab_channel()) {
      // Decoded and checked by the session (a corrupt message is counted there, not decoded here).
      if (offset_us) session.advance_model(ev->timestamp + *offset_us);
      session.on_cloud(ev->data, static_cast<std::size_t>(ev->datalen), ch, offset_us ? ev->timestamp + *offset_us : 0);
    } else if (!frame_channel.empty() && ch == frame_channel) {
      arnav::image_frame_t m;
      if (m.decode(ev->data, 0, ev->datalen) < 0) { ++undecodable; continue; }
      const std::int64_t t = now(m.capture_time_mono_us, m.capture_time_wall_us);
      session.advance_model(t);
      session.render_frame(m, t);
      if (session.window_closed()) {
        std::cout << "arnav-host: the display window was closed: ending the replay" << std::endl;
        break;
      }
    }
    if (offset_us && !cli.quiet) {
      if (next_print < 0) next_print = last_now;
      if (last_now >= next_print) {
        std::cout << session.status_table(last_now) << "\n" << security.describe() << "; " << arnav::seal::format_counters(opener.counters())
                  << std::endl;
        next_print += static_cast<std::int64_t>(cli.print_period_s * 1e6);
      }
    }
  }
  if (const std::string problem = opener.problem(cli.replay_log); !problem.empty() && messages > 0) {
    std::cerr << "arnav-host: --replay " << problem << "\n";
    session.stop();
    return 2;
  }
  if (undecodable > 0)
    std::cerr << "arnav-host: --replay " << cli.replay_log << ": " << undecodable << " of " << messages
              << " messages could not be decoded (another schema version?)\n";
  session.stop();
  const double run_s = first_ts >= 0 && offset_us ? static_cast<double>(last_now - (first_ts + *offset_us)) * 1e-6 : 0.0;
  const auto tracker = session.tracker_at(last_now);
  std::cout << format_status_table(tracker, last_now) << "arnav-host: replay " << security.describe() << "; "
            << arnav::seal::format_counters(opener.counters()) << std::endl;
  if (cli.print_summary) std::cout << format_summary(tracker, run_s) << session.format_summary(run_s) << std::flush;
  for (const auto& f : session.recorded_files()) std::cout << "recorded: " << f << "\n";
  nlohmann::json j = summary(tracker, run_s);
  j["navigation"] = session.summary_json(run_s);
  j["replay"] = {{"log", cli.replay_log}, {"messages", messages}, {"undecodable", undecodable}};
  j["security"] = security_json(security, opener.counters(), opener.sealed_without_key());
  return write_summary(cli, j);
}

int run_session(const Cli& cli) {
  arnav::host::SessionConfig config;
  std::unique_ptr<arnav::host::Scene> scene;
  try {
    config = arnav::host::load_session(cli.session_path);
    if (config.scene_path) {
      try {
        scene = std::make_unique<arnav::host::Scene>(arnav::host::load_scene(*config.scene_path));
      } catch (const arnav::host::LoadError& e) {
        throw arnav::host::SessionError(config.source + ":" + std::to_string(config.scene_line) + ": key 'scene': " + e.what());
      }
    }
  } catch (const arnav::host::SessionError& e) {
    std::cerr << "arnav-host: " << e.what() << "\n";
    return 2;
  }
  const std::optional<arnav::seal::BusSecurity> security = session_security(config);
  if (!security) return 2;
  arnav::host::SessionOptions options;
  options.threaded = cli.replay_log.empty();
  options.record_dir = cli.record_dir;
  options.print_events = true;  // cut events, landmark takes, input disarms: rare, always printed
  std::unique_ptr<arnav::host::NavigationSession> session;
  try {
    session = std::make_unique<arnav::host::NavigationSession>(config, std::move(scene), options);
  } catch (const arnav::host::SessionError& e) {
    std::cerr << "arnav-host: " << e.what() << "\n";
    return 2;
  }
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  if (!cli.replay_log.empty()) {
    try {
      session->open_window();  // display.window: on this thread, which renders the replay
    } catch (const arnav::host::DisplayUnavailable& e) {
      std::cerr << "arnav-host: " << e.what() << "\n";
      return 2;
    }
    return run_replay(cli, *session, config.camera ? arnav::channels::frame(config.camera->name) : std::string(), *security);
  }

  arnav::seal::SealedLcm bus(config.lcm_url, *security);
  if (!bus.good()) {
    std::cerr << "arnav-host: " << config.source << ": cannot open LCM at '" << config.lcm_url
              << "': check lcm_url (udpm needs a multicast route, e.g. 224.0.0.0/4 on the interface)\n";
    return 2;
  }
  arnav::host::SessionHandler handler{{*session, cli.events}};
  arnav::host::connect_session(bus, handler, config.camera ? arnav::channels::frame(config.camera->name) : std::string());
  const std::int64_t model_started_mono_us = arnav::monotonic_us();  // the surfaces' rest state holds from here
  try {
    session->start();
  } catch (const arnav::host::DisplayUnavailable& e) {
    std::cerr << "arnav-host: " << e.what() << "\n";
    return 2;
  }
  // The model's surfaces for other programs (arnav-igtl), off the model thread.
  std::unique_ptr<arnav::host::SurfacePublisher> surfaces;
  if (session->has_model() && config.surfaces.publish_rate_hz > 0) {
    arnav::host::NavigationSession& s = *session;
    surfaces = std::make_unique<arnav::host::SurfacePublisher>(
        config.surfaces.publish_rate_hz, [&s] { return arnav::host::SurfaceSource{s.model_snapshot(), s.X_RefModel()}; },
        [&bus](const std::string& channel, const arnav::surface_mesh_t& mesh) { return bus.publish(channel, &mesh) >= 0; },
        s.cpu_plan().active ? s.cpu_plan().render_cpus : std::vector<int>{}, model_started_mono_us);
    std::cout << "arnav-host: publishing the model's surfaces on " << arnav::channels::kSurfacePrefix << "* at "
              << config.surfaces.publish_rate_hz << " Hz (surfaces.publish_rate_hz)" << std::endl;
  }
  // Scene loaded, model built, subscribed: what the bench waits for before it starts the appliance.
  std::cout << "arnav-host: session ready: " << config.source << (config.camera ? " (overlay on ARNAV_FRAME_" + config.camera->name + ")" : " (status monitor)")
            << std::endl;
  const std::int64_t t0 = arnav::monotonic_us();
  std::int64_t next_print = t0 + static_cast<std::int64_t>(config.print_period_s * 1e6);
  while (!g_stop.load()) {
    if (bus.handleTimeout(20) < 0) {
      if (g_stop.load()) break;  // interrupted by SIGTERM/SIGINT
      std::cerr << "arnav-host: LCM receive failed\n";
      return 1;
    }
    const std::int64_t now = arnav::monotonic_us();
    if (const std::string failed = session->failure(); !failed.empty()) {
      std::cerr << "arnav-host: " << failed << "\n";
      session->stop();
      return 1;
    }
    if (!cli.quiet && now >= next_print) {
      std::cout << session->status_table(now) << "\n" << bus.status_line() << std::endl;
      next_print += static_cast<std::int64_t>(config.print_period_s * 1e6);
    }
    if (cli.duration_s > 0 && now - t0 >= static_cast<std::int64_t>(cli.duration_s * 1e6)) break;
    if (session->window_closed()) {
      std::cout << "arnav-host: the display window was closed: ending the session" << std::endl;
      break;
    }
  }
  if (surfaces) surfaces->stop();
  try {
    session->stop();
  } catch (const arnav::host::SessionError& e) {
    std::cerr << "arnav-host: " << e.what() << "\n";
    return 1;
  }
  const std::int64_t now = arnav::monotonic_us();
  const double run_s = static_cast<double>(now - t0) * 1e-6;
  const auto tracker = session->tracker_at(now);
  std::cout << format_status_table(tracker, now) << bus.status_line() << std::endl;
  if (cli.print_summary) {
    std::cout << format_summary(tracker, run_s);
    if (config.camera || session->has_model()) std::cout << session->format_summary(run_s);
    std::cout << std::flush;
  }
  for (const auto& f : session->recorded_files()) std::cout << "recorded: " << f << "\n";
  nlohmann::json j = summary(tracker, run_s);
  if (config.camera || session->has_model()) j["navigation"] = session->summary_json(run_s);
  const arnav::seal::BusCounters bc = bus.counters();
  j["security"] = security_json(*security, bc.open, bc.sealed_on_off_bus, &bc.senders);
  if (surfaces) {
    const auto st = surfaces->stats();
    j["surfaces"] = {{"publish_rate_hz", config.surfaces.publish_rate_hz}, {"rounds", st.rounds}, {"rounds_unregistered", st.rounds_unregistered},
                     {"messages", st.messages}, {"model_steps", st.model_steps}, {"publish_failures", st.publish_failures}, {"build_ms_max", st.build_ms_max},
                     {"pin_error", surfaces->pin_error()}};
  }
  return write_summary(cli, j);
}

}  // namespace

static int main_body(int argc, char** argv) {
  CLI::App app{"arnav-host: navigation session (SESSION.yaml: overlay, model, recording) or, without one, the pose/health status monitor"};
  Cli cli;
  std::string& lcm_url = cli.lcm_url;
  double &stale_after_ms = cli.stale_after_ms, &print_period_s = cli.print_period_s, &duration_s = cli.duration_s;
  std::string& summary_path = cli.summary_path;
  bool &quiet = cli.quiet, &events = cli.events, &print_summary = cli.print_summary;
  app.add_option("session", cli.session_path, "session file (docs/overlay.md); without it: status monitor");
  app.add_option("--record", cli.record_dir, "write overlay.avi, overlay.csv and contact_sheet.png into this folder");
  app.add_option("--replay", cli.replay_log, "re-run the session on an lcm-logger log instead of the live bus");
  app.add_option("--replay-speed", cli.replay_speed, "1 = the log's pace (default), 2 = twice as fast, 0 = as fast as possible")
      ->check(CLI::Range(0.0, 1000.0));
  app.add_option("--lcm-url", lcm_url, "LCM URL (default: the appliance's, TTL 0)");
  app.add_option("--stale-after-ms", stale_after_ms, "a tool is stale when its last valid pose is older (default 250)")
      ->check(CLI::Range(1.0, 600000.0));
  app.add_option("--print-period", print_period_s, "seconds between status tables (default 1)")->check(CLI::Range(0.05, 3600.0));
  app.add_option("--duration", duration_s, "exit after this many seconds (default: run until SIGINT/SIGTERM)")->check(CLI::Range(0.0, 1e7));
  app.add_option("--summary-json", summary_path, "write a JSON summary (per tool, per device, events) at exit");
  app.add_flag("--quiet", quiet, "no periodic table (final table only)");
  app.add_flag("--events", events, "print appliance events as they arrive");
  app.add_flag("--summary", print_summary, "print a summary at exit (rates, outages, device counters, latency, events)");
  app.add_option("--key", cli.key_file, "status monitor: the bus key (arnav-keygen; docs/protocol.md)");
  app.add_option("--security", cli.security, "status monitor: 'off' for a bus that is not sealed (bench only)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  if (cli.session_path.empty() && (!cli.record_dir.empty() || !cli.replay_log.empty())) {
    std::cerr << "arnav-host: --record and --replay need a session file: arnav-host SESSION.yaml ...\n";
    return 2;
  }
  if (!cli.session_path.empty()) {
    for (const char* opt : {"--lcm-url", "--stale-after-ms", "--print-period", "--key", "--security"})
      if (app.count(opt) > 0) {
        std::cerr << "arnav-host: " << opt << " belongs to the status monitor; with a session file set it there (lcm_url, stale_after_ms, print_period_s, security)\n";
        return 2;
      }
    try {
      return run_session(cli);
    } catch (const std::exception& e) {
      std::cerr << "arnav-host: " << e.what() << "\n";
      return 1;
    }
  }
  arnav::seal::BusSecurity security;
  try {
    security = arnav::seal::security_from_cli(cli.key_file, cli.security, "arnav-host");
  } catch (const arnav::seal::SecurityError& e) {
    std::cerr << e.what() << "\n";
    return 2;
  }
  std::cout << "arnav-host: " << security.describe() << std::endl;
  arnav::seal::SealedLcm bus(lcm_url, security);
  if (!bus.good()) {
    std::cerr << "arnav-host: cannot open LCM at '" << lcm_url
              << "': check the URL (udpm needs a multicast route, e.g. 224.0.0.0/4 on the interface)\n";
    return 2;
  }
  arnav::host::ToolFreshnessTracker tracker(static_cast<std::int64_t>(stale_after_ms * 1000.0));
  Handler handler{tracker, events};
  bus.subscribe(std::string(arnav::channels::kPoseRegex), &Handler::pose, &handler);
  bus.subscribe(std::string(arnav::channels::kHealthRegex), &Handler::health, &handler);
  bus.subscribe(std::string(arnav::channels::kEvents), &Handler::event, &handler);
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);

  const std::int64_t t0 = arnav::monotonic_us();
  std::int64_t next_print = t0 + static_cast<std::int64_t>(print_period_s * 1e6);
  while (!g_stop.load()) {
    if (bus.handleTimeout(20) < 0) {
      if (g_stop.load()) break;  // interrupted by SIGTERM/SIGINT
      std::cerr << "arnav-host: LCM receive failed\n";
      return 1;
    }
    const std::int64_t now = arnav::monotonic_us();
    tracker.update(now);
    if (!quiet && now >= next_print) {
      std::cout << format_status_table(tracker, now) << bus.status_line() << std::endl;
      next_print += static_cast<std::int64_t>(print_period_s * 1e6);
    }
    if (duration_s > 0 && now - t0 >= static_cast<std::int64_t>(duration_s * 1e6)) break;
  }
  const std::int64_t now = arnav::monotonic_us();
  tracker.update(now);
  const double run_s = static_cast<double>(now - t0) * 1e-6;
  std::cout << format_status_table(tracker, now) << bus.status_line() << std::endl;
  if (print_summary) std::cout << format_summary(tracker, run_s) << std::flush;
  if (!summary_path.empty()) {
    nlohmann::json j = summary(tracker, run_s);
    const arnav::seal::BusCounters bc = bus.counters();
    j["security"] = security_json(security, bc.open, bc.sealed_on_off_bus, &bc.senders);
    std::ofstream out(summary_path);
    out << j.dump(2) << "\n";
    if (!out) {
      std::cerr << "arnav-host: cannot write " << summary_path << "\n";
      return 1;
    }
  }
  return 0;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-host", [&] { return main_body(argc, argv); });
}
