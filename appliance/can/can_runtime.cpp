#include "appliance/can/can_runtime.hpp"

#include <sys/stat.h>

#include <cstdio>
#include <iostream>

#include "appliance/realtime/realtime.hpp"
#include "appliance/can/slcan_transport.hpp"
#include "appliance/can/socketcan_transport.hpp"
#include "appliance/serial/posix_transport.hpp"
#include "appliance/serial/serial_transport.hpp"
#include "protocol/channels.hpp"
#include "protocol/clock.hpp"

namespace arnav::can {
namespace {

bool is_char_device(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISCHR(st.st_mode);
}

std::string hex_id(std::uint32_t id, bool ext) {
  char b[16];
  std::snprintf(b, sizeof b, ext ? "0x%08X" : "0x%03X", id);
  return b;
}

}  // namespace

std::unique_ptr<CanTransport> open_transport(const CanConfig& c) {
  if (!c.slcan) return std::make_unique<SocketCanTransport>(c.interface, c.ids());
  std::unique_ptr<ndi::Transport> port;
  try {
    bool listed = false;
    try {
      listed = ndi::port_exists(c.port);
    } catch (...) {
    }
    if (listed) port = std::make_unique<ndi::SerialTransport>(c.port);
    else if (is_char_device(c.port)) port = std::make_unique<ndi::PosixTransport>(c.port);
    else
      throw CanUnavailable(CanUnavailable::Kind::NoInterface,
                           c.interface + ": no serial port '" + c.port + "' (is the slcan adapter plugged in? `arnav-ndi ports` lists the ports)");
    port->set_baud(c.serial_baud);
  } catch (const ndi::PortError& e) {
    throw CanUnavailable(CanUnavailable::Kind::NoInterface, c.interface + ": " + e.what());
  } catch (const ndi::PortLost& e) {
    throw CanUnavailable(CanUnavailable::Kind::NoInterface, c.interface + ": " + e.what());
  }
  SlcanOptions o;
  o.bitrate = c.bitrate;
  o.status_poll = std::chrono::milliseconds(c.status_poll_ms);
  return std::make_unique<SlcanTransport>(std::move(port), c.interface, o);
}

CanService::CanService(CanConfig config, seal::SealedLcm& lcm, TransportFactory factory, double health_rate_hz)
    : config_(std::move(config)),
      lcm_(lcm),
      factory_(std::move(factory)),
      decoder_(config_),
      health_channel_(channels::health("can")),
      health_period_us_(static_cast<std::int64_t>(1e6 / health_rate_hz)) {
  msg_.source_interface = config_.interface;
  const std::int64_t now = monotonic_us();
  next_health_us_ = now + health_period_us_;
  window_start_us_ = now;
}

CanService::~CanService() = default;

void CanService::event(std::int8_t severity, const std::string& code, const std::string& text) {
  appliance_event_t e{};
  e.source = "can";
  e.severity = severity;
  e.code = code;
  e.text = text;
  e.time_mono_us = monotonic_us();
  e.time_wall_us = wall_us();
  e.sequence = ++event_sequence_;
  std::cerr << "arnav-appliance: [can] " << (severity == appliance_event_t::SEVERITY_INFO ? "info" : severity == appliance_event_t::SEVERITY_WARNING ? "WARNING" : "ERROR")
            << " " << code << ": " << text << "\n";
  lcm_.publish(std::string(channels::kEvents), &e);
}

void CanService::on_input(const InputChange& c) {
  const InputConfig& in = config_.inputs[c.input];
  msg_.input_name = in.name;
  msg_.state = c.pressed ? +input_event_t::STATE_PRESSED : +input_event_t::STATE_RELEASED;
  msg_.value = c.value;
  switch (c.cause) {
    case InputChange::Cause::Frame: msg_.cause = +input_event_t::CAUSE_FRAME; break;
    case InputChange::Cause::Debounce: msg_.cause = +input_event_t::CAUSE_DEBOUNCE; break;
    case InputChange::Cause::NodeLost: msg_.cause = transport_ ? +input_event_t::CAUSE_DEVICE_LOST : +input_event_t::CAUSE_LINK_LOST; break;
    case InputChange::Cause::BusOff: msg_.cause = +input_event_t::CAUSE_BUS_OFF; break;
  }
  msg_.device = config_.nodes[in.node].name;
  const bool from_frame = c.frame_us != 0 && (c.cause == InputChange::Cause::Frame || c.cause == InputChange::Cause::Debounce);
  msg_.device_time_wall_us = from_frame && c.frame_us == rx_.receive_mono_us ? rx_.device_wall_us : -1;
  msg_.receive_time_mono_us = from_frame ? c.frame_us : 0;
  const std::int64_t now_mono = monotonic_us();
  msg_.receive_time_wall_us = from_frame ? wall_us() - (now_mono - c.frame_us) : 0;
  msg_.decided_time_mono_us = c.decided_us;
  msg_.sequence = ++input_sequence_;
  msg_.publish_time_wall_us = wall_us();
  msg_.publish_time_mono_us = monotonic_us();
  lcm_.publish(std::string(channels::kInput), &msg_);
  if (input_listener_) input_listener_(in.name, c.pressed);
  if (from_frame) latency_.add(static_cast<float>(monotonic_us() - c.decided_us));
  if (c.cause == InputChange::Cause::NodeLost || c.cause == InputChange::Cause::BusOff)
    event(appliance_event_t::SEVERITY_WARNING, "CAN_INPUT_FORCED_RELEASE",
          in.name + " released: " + (c.cause == InputChange::Cause::BusOff ? "the bus went off" : "device '" + msg_.device + "' lost"));
}

void CanService::on_node(const NodeChange& c) {
  const NodeConfig& n = config_.nodes[c.node];
  const std::string what = n.liveness == NodeConfig::Liveness::Heartbeat
                               ? "heartbeat " + hex_id(n.id, false) + " (CANopen node " + std::to_string(n.node_id) + ")"
                               : "frame " + hex_id(n.id, n.extended);
  if (c.state == NodeState::Lost && !transport_) {
    if (!closing_)
      event(appliance_event_t::SEVERITY_WARNING, "CAN_DEVICE_LOST", "device '" + n.name + "': " + config_.interface + " is closed; its inputs are released");
  } else if (c.state == NodeState::Lost) {
    last_fault_ = "device " + n.name + " lost";
    event(appliance_event_t::SEVERITY_ERROR, "CAN_DEVICE_LOST",
          "device '" + n.name + "' on " + config_.interface + ": no " + what + " for " + std::to_string(c.silent_us / 1000) +
              " ms (timeout " + std::to_string(n.timeout_ms) + " ms); its inputs are released");
  } else if (c.previous == NodeState::Lost) {
    event(appliance_event_t::SEVERITY_INFO, "CAN_DEVICE_BACK", "device '" + n.name + "' on " + config_.interface + " is back (" + what + ")");
  } else if (c.previous == NodeState::Unknown) {
    event(appliance_event_t::SEVERITY_INFO, "CAN_DEVICE_ALIVE", "device '" + n.name + "' on " + config_.interface + " seen (" + what + ")");
  } else {
    event(appliance_event_t::SEVERITY_INFO, "CAN_DEVICE_STATE",
          "device '" + n.name + "' reports CANopen state " + std::string(canopen_state_name(c.canopen_state)));
  }
}

void CanService::on_bus(const BusChange& c) {
  const std::string where = config_.interface + ": ";
  switch (c.state) {
    case BusState::BusOff:
      last_fault_ = "bus-off";
      event(appliance_event_t::SEVERITY_ERROR, "CAN_BUS_OFF",
            where + "the controller went bus-off (too many errors: wiring, termination, bit rate?); every input released" +
                (config_.slcan ? "; reopening the slcan channel" : "; waiting for the kernel to restart it (restart-ms)"));
      break;
    case BusState::Passive:
      event(appliance_event_t::SEVERITY_WARNING, "CAN_ERROR_PASSIVE", where + "controller error-passive (many bus errors)");
      break;
    case BusState::Warning:
      event(appliance_event_t::SEVERITY_WARNING, "CAN_ERROR_WARNING", where + "controller error counters above the warning level");
      break;
    case BusState::Active:
      if (c.previous == BusState::BusOff)
        event(appliance_event_t::SEVERITY_INFO, "CAN_BUS_RECOVERED", where + "the controller is back on the bus after bus-off");
      else
        event(appliance_event_t::SEVERITY_INFO, "CAN_ERROR_ACTIVE", where + "controller error-active again");
      break;
  }
}

void CanService::try_open(std::int64_t now) {
  try {
    transport_ = factory_();
    open_failure_reported_ = false;
    if (ever_open_) ++reconnects_;
    ever_open_ = true;
    event(appliance_event_t::SEVERITY_INFO, "CAN_OPEN",
          config_.interface + " open" + (transport_->detail().empty() ? "" : " (" + transport_->detail() + ")") + ", " +
              std::to_string(config_.inputs.size()) + " input(s), " + std::to_string(config_.nodes.size()) + " device(s)");
  } catch (const CanUnavailable& e) {
    last_fault_ = e.what();
    if (e.kind() == CanUnavailable::Kind::NoAfCan) {
      unavailable_forever_ = true;
      event(appliance_event_t::SEVERITY_ERROR, "CAN_UNAVAILABLE",
            std::string(e.what()) + ". The CAN inputs are off; everything else keeps running.");
    } else if (!open_failure_reported_) {
      open_failure_reported_ = true;
      event(appliance_event_t::SEVERITY_ERROR, "CAN_OPEN_FAILED", std::string(e.what()) + " (retrying every second)");
    }
    next_open_us_ = now + 1'000'000;
  }
}

void CanService::step(std::chrono::microseconds max_wait) {
  std::int64_t now = monotonic_us();
  if (!transport_ && !unavailable_forever_ && now >= next_open_us_) try_open(now);
  if (transport_) {
    const std::int64_t until = std::min({decoder_.next_deadline_us(), next_health_us_, now + max_wait.count()});
    try {
      if (transport_->receive(rx_, std::chrono::microseconds(std::max<std::int64_t>(0, until - now)))) {
        decoder_.tick(rx_.receive_mono_us, *this);
        decoder_.on_frame(rx_.frame, rx_.receive_mono_us, *this);
      }
    } catch (const CanLinkLost& e) {
      last_fault_ = e.what();
      closed_counters_ += transport_->counters();
      transport_.reset();
      event(appliance_event_t::SEVERITY_ERROR, "CAN_LINK_LOST", std::string(e.what()) + "; every input released, reopening");
      decoder_.link_lost(monotonic_us(), *this);
      next_open_us_ = monotonic_us() + 200'000;
    }
  } else {
    const std::int64_t until = std::min({next_health_us_, next_open_us_, now + max_wait.count()});
    if (until > now) std::this_thread::sleep_for(std::chrono::microseconds(until - now));
  }
  now = monotonic_us();
  decoder_.tick(now, *this);
  if (now >= next_health_us_) publish_health(now);
}

device_health_t CanService::fill_health(const app::LatencySummary& l, double rate) const {
  TransportCounters t = closed_counters_;
  if (transport_) t += transport_->counters();
  const DecoderCounters& d = decoder_.counters();
  device_health_t h{};
  h.device = "can";
  if (!transport_) h.link_state = unavailable_forever_ || !ever_open_ ? +device_health_t::LINK_DOWN : +device_health_t::LINK_CONNECTING;
  else if (decoder_.bus_state() == BusState::BusOff) h.link_state = +device_health_t::LINK_RECOVERING;
  else h.link_state = +device_health_t::LINK_TRACKING;
  h.port = config_.interface;
  h.baud = config_.slcan ? config_.serial_baud : 0;
  h.firmware = transport_ ? transport_->detail() : "";
  h.frame_rate_hz = static_cast<float>(rate);
  h.frames_total = t.frames;
  h.crc_errors = t.malformed;
  std::int64_t losses = 0;
  for (const auto& n : decoder_.nodes()) losses += n.losses;
  h.timeouts = losses;
  h.resyncs = t.resyncs;
  h.garbage_bytes = t.garbage_bytes;
  h.error_replies = t.error_frames;
  h.resets = d.bus_off;
  h.reconnects = reconnects_;
  h.dropped_frames = t.overruns;
  h.latency_p50_us = l.p50_us;
  h.latency_p99_us = l.p99_us;
  h.latency_max_us = l.max_us;
  std::string detail = unavailable_forever_ ? "unavailable" : transport_ ? "bus " + std::string(to_string(decoder_.bus_state())) : "closed";
  detail += "; devices:";
  for (std::size_t i = 0; i < config_.nodes.size(); ++i) {
    const NodeStatus& n = decoder_.nodes()[i];
    detail += " " + config_.nodes[i].name + "=" + std::string(to_string(n.state));
    if (n.canopen_state != 0xFF && n.state == NodeState::Alive) detail += "(" + std::string(canopen_state_name(n.canopen_state)) + ")";
  }
  detail += "; pressed:";
  bool any = false;
  for (std::size_t i = 0; i < config_.inputs.size(); ++i)
    if (decoder_.inputs()[i].pressed) {
      detail += " " + config_.inputs[i].name;
      any = true;
    }
  if (!any) detail += " none";
  detail += "; presses " + std::to_string(d.presses) + ", releases " + std::to_string(d.releases) + " (forced " +
            std::to_string(d.forced_releases) + "), unrelated frames " + std::to_string(d.unrelated) + ", restarts " + std::to_string(d.restarts);
  if (!last_fault_.empty()) detail += "; last fault: " + last_fault_;
  h.detail = detail;
  h.publish_time_mono_us = monotonic_us();
  h.publish_time_wall_us = wall_us();
  return h;
}

device_health_t CanService::health() const { return fill_health({}, 0.0); }

void CanService::publish_health(std::int64_t now) {
  const std::int64_t frames = decoder_.counters().frames;
  const double rate = static_cast<double>(frames - frames_at_window_) * 1e6 / static_cast<double>(std::max<std::int64_t>(1, now - window_start_us_));
  frames_at_window_ = frames;
  window_start_us_ = now;
  const device_health_t h = fill_health(latency_.take(), rate);
  lcm_.publish(health_channel_, &h);
  // Every input's state, so a subscriber that lost a change (UDP) converges within a period.
  input_event_t snap{};
  snap.source_interface = config_.interface;
  snap.cause = +input_event_t::CAUSE_STATE;
  snap.device_time_wall_us = -1;
  snap.sequence = input_sequence_;
  for (std::size_t i = 0; i < config_.inputs.size(); ++i) {
    const InputConfig& in = config_.inputs[i];
    const InputStatus& st = decoder_.inputs()[i];
    snap.input_name = in.name;
    snap.device = config_.nodes[in.node].name;
    snap.state = st.pressed ? +input_event_t::STATE_PRESSED : +input_event_t::STATE_RELEASED;
    snap.value = st.value;
    snap.publish_time_mono_us = monotonic_us();
    snap.publish_time_wall_us = wall_us();
    lcm_.publish(std::string(channels::kInputState), &snap);
  }
  next_health_us_ = now + health_period_us_;
}

void CanService::shutdown() {
  const std::int64_t now = monotonic_us();
  closing_ = true;
  transport_.reset();
  event(appliance_event_t::SEVERITY_INFO, "CAN_CLOSED", config_.interface + " closed (appliance stopping); every input released");
  decoder_.link_lost(now, *this);
  publish_health(now);
}

std::unique_ptr<CanRuntime> CanRuntime::load(const std::filesystem::path& config_file) {
  auto c = load_can_config(config_file);
  if (!c) return nullptr;
  return std::make_unique<CanRuntime>(std::move(*c));
}

CanRuntime::~CanRuntime() { stop(); }

std::string CanRuntime::summary() const {
  return "CAN " + config_.interface + ": " + std::to_string(config_.inputs.size()) + " input(s), " + std::to_string(config_.nodes.size()) + " device(s)";
}

void CanRuntime::start(const std::string& lcm_url, const seal::BusSecurity& security, double health_rate_hz) {
  lcm_ = std::make_unique<seal::SealedLcm>(lcm_url, security);
  if (!lcm_->good()) throw CanConfigError(config_.source + ": key 'lcm_url': cannot open LCM at '" + lcm_url + "'");
  const CanConfig cfg = config_;
  service_ = std::make_unique<CanService>(config_, *lcm_, [cfg] { return open_transport(cfg); }, health_rate_hz);
  if (input_listener_) service_->set_input_listener(input_listener_);
  stop_ = false;
  thread_ = std::thread([this] {
    if (const std::string error = app::make_this_thread_realtime(config_.priority); !error.empty())
      service_->event(appliance_event_t::SEVERITY_WARNING, "CAN_REALTIME_DENIED", "CAN thread: " + error);
    while (!stop_) service_->step(std::chrono::milliseconds(50));
    service_->shutdown();
  });
}

void CanRuntime::stop() {
  if (!thread_.joinable()) return;
  stop_ = true;
  thread_.join();
}

}  // namespace arnav::can
