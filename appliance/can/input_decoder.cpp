#include "appliance/can/input_decoder.hpp"

#include <algorithm>
#include <limits>

namespace arnav::can {

std::string_view to_string(NodeState s) {
  switch (s) {
    case NodeState::Unknown: return "unknown";
    case NodeState::Alive: return "alive";
    case NodeState::Lost: return "lost";
  }
  return "?";
}

std::string_view to_string(BusState s) {
  switch (s) {
    case BusState::Active: return "error-active";
    case BusState::Warning: return "error-warning";
    case BusState::Passive: return "error-passive";
    case BusState::BusOff: return "bus-off";
  }
  return "?";
}

std::string_view canopen_state_name(std::uint8_t state) {
  switch (state & 0x7F) {
    case 0x00: return "boot-up";
    case 0x04: return "stopped";
    case 0x05: return "operational";
    case 0x7F: return "pre-operational";
    default: return "unknown";
  }
}

InputDecoder::InputDecoder(CanConfig config)
    : config_(std::move(config)), status_(config_.inputs.size()), raw_(config_.inputs.size()), nodes_(config_.nodes.size()) {}

void InputDecoder::set_bus(BusState s, std::int64_t now_us, DecoderSink& sink) {
  if (s == bus_) return;
  const BusState prev = bus_;
  bus_ = s;
  if (s == BusState::BusOff) {
    counters_.bus_off += 1;
    release_all(now_us, sink, InputChange::Cause::BusOff, false, 0);
  } else if (prev == BusState::BusOff) {
    counters_.restarts += 1;
  }
  sink.on_bus({s, prev, now_us});
}

void InputDecoder::release_all(std::int64_t now_us, DecoderSink& sink, InputChange::Cause cause, bool only_node, std::size_t node) {
  for (std::size_t i = 0; i < raw_.size(); ++i) {
    if (only_node && config_.inputs[i].node != node) continue;
    raw_[i] = Raw{false, 0.0, now_us, 0};
    if (status_[i].pressed) {
      status_[i] = {false, 0.0};
      counters_.releases += 1;
      counters_.forced_releases += 1;
      sink.on_input({i, false, 0.0, 0, now_us, cause});
    } else {
      status_[i].value = 0.0;
    }
  }
}

void InputDecoder::node_seen(std::size_t n, std::int64_t now_us, DecoderSink& sink, std::uint8_t canopen_state) {
  NodeStatus& s = nodes_[n];
  s.last_seen_us = now_us;
  const std::uint8_t prev_canopen = s.canopen_state;
  s.canopen_state = canopen_state;
  if (s.state != NodeState::Alive) {
    const NodeState prev = s.state;
    s.state = NodeState::Alive;
    sink.on_node({n, NodeState::Alive, prev, now_us, 0, canopen_state});
  } else if (canopen_state != prev_canopen) {
    sink.on_node({n, NodeState::Alive, NodeState::Alive, now_us, 0, canopen_state});
  }
}

void InputDecoder::on_frame(const CanFrame& f, std::int64_t receive_us, DecoderSink& sink) {
  if (f.error) {
    counters_.error_frames += 1;
    if (f.id & err::kBusOff) set_bus(BusState::BusOff, receive_us, sink);
    else if (f.id & err::kRestarted) set_bus(BusState::Active, receive_us, sink);
    else if (f.id & err::kCrtl) {
      const std::uint8_t d = f.data[1];
      if (d & (err::kCrtlRxPassive | err::kCrtlTxPassive)) set_bus(BusState::Passive, receive_us, sink);
      else if (d & (err::kCrtlRxWarning | err::kCrtlTxWarning)) set_bus(BusState::Warning, receive_us, sink);
      else if (d & err::kCrtlActive) set_bus(BusState::Active, receive_us, sink);
    }
    return;
  }
  counters_.frames += 1;
  // A controller that delivers frames is on the bus again, whether or not the driver
  // reported the restart.
  if (bus_ == BusState::BusOff) set_bus(BusState::Active, receive_us, sink);
  bool matched = false;
  for (std::size_t n = 0; n < nodes_.size(); ++n) {
    const NodeConfig& nc = config_.nodes[n];
    if (nc.id != f.id || nc.extended != f.extended) continue;
    if (nc.liveness == NodeConfig::Liveness::Heartbeat) {
      if (f.remote || f.dlc < 1) continue;  // a heartbeat carries its NMT state byte
      node_seen(n, receive_us, sink, f.data[0]);
    } else {
      node_seen(n, receive_us, sink, 0xFF);
    }
    matched = true;
  }
  for (std::size_t i = 0; i < raw_.size(); ++i) {
    const InputConfig& in = config_.inputs[i];
    if (in.id != f.id || in.extended != f.extended || f.remote) continue;
    matched = true;
    if (f.dlc < in.byte + (in.analog ? in.size : 1)) {
      counters_.short_frames += 1;
      continue;
    }
    if (nodes_[in.node].state != NodeState::Alive) continue;  // an unproven device presses nothing
    Raw& r = raw_[i];
    bool level = r.level;
    double value = 0.0;
    const auto b = static_cast<std::size_t>(in.byte);
    if (in.analog) {
      value = in.size == 1 ? f.data[b]
                           : (in.big_endian ? (f.data[b] << 8) | f.data[b + 1] : f.data[b] | (f.data[b + 1] << 8));
      if (value >= in.press_at) level = true;
      else if (value <= in.release_at) level = false;  // in between: keep (hysteresis)
    } else {
      const bool bit = (f.data[b] >> in.bit) & 1u;
      level = bit == in.active_high;
      value = level ? 1.0 : 0.0;
    }
    r.value = value;
    if (level != r.level) {
      r.level = level;
      r.since_us = receive_us;
      r.frame_us = receive_us;
    }
    status_[i].value = status_[i].pressed == level ? value : status_[i].value;
    evaluate(i, receive_us, sink, InputChange::Cause::Frame);
  }
  if (!matched) counters_.unrelated += 1;
  else counters_.matched += 1;
}

void InputDecoder::evaluate(std::size_t i, std::int64_t now_us, DecoderSink& sink, InputChange::Cause cause) {
  Raw& r = raw_[i];
  if (r.level == status_[i].pressed) return;
  const InputConfig& in = config_.inputs[i];
  const std::int64_t hold_us = static_cast<std::int64_t>(r.level ? in.debounce_ms : in.release_debounce_ms) * 1000;
  if (now_us - r.since_us < hold_us) return;
  const std::int64_t decided = std::max(r.since_us + hold_us, r.frame_us);
  status_[i] = {r.level, r.value};
  if (r.level) counters_.presses += 1;
  else counters_.releases += 1;
  sink.on_input({i, r.level, r.value, r.frame_us, decided, cause});
}

void InputDecoder::tick(std::int64_t now_us, DecoderSink& sink) {
  for (std::size_t n = 0; n < nodes_.size(); ++n) {
    NodeStatus& s = nodes_[n];
    if (s.state != NodeState::Alive) continue;
    const std::int64_t silent = now_us - s.last_seen_us;
    if (silent <= static_cast<std::int64_t>(config_.nodes[n].timeout_ms) * 1000) continue;
    s.state = NodeState::Lost;
    s.losses += 1;
    release_all(now_us, sink, InputChange::Cause::NodeLost, true, n);
    sink.on_node({n, NodeState::Lost, NodeState::Alive, now_us, silent, s.canopen_state});
  }
  for (std::size_t i = 0; i < raw_.size(); ++i)
    if (nodes_[config_.inputs[i].node].state == NodeState::Alive) evaluate(i, now_us, sink, InputChange::Cause::Debounce);
}

std::int64_t InputDecoder::next_deadline_us() const {
  std::int64_t t = std::numeric_limits<std::int64_t>::max();
  for (std::size_t n = 0; n < nodes_.size(); ++n)
    if (nodes_[n].state == NodeState::Alive)
      t = std::min(t, nodes_[n].last_seen_us + static_cast<std::int64_t>(config_.nodes[n].timeout_ms) * 1000 + 1);
  for (std::size_t i = 0; i < raw_.size(); ++i) {
    if (raw_[i].level == status_[i].pressed || nodes_[config_.inputs[i].node].state != NodeState::Alive) continue;
    const InputConfig& in = config_.inputs[i];
    t = std::min(t, raw_[i].since_us + static_cast<std::int64_t>(raw_[i].level ? in.debounce_ms : in.release_debounce_ms) * 1000);
  }
  return t;
}

void InputDecoder::link_lost(std::int64_t now_us, DecoderSink& sink) {
  release_all(now_us, sink, InputChange::Cause::NodeLost, false, 0);
  for (std::size_t n = 0; n < nodes_.size(); ++n) {
    NodeStatus& s = nodes_[n];
    if (s.state != NodeState::Alive) continue;
    s.state = NodeState::Lost;
    s.losses += 1;
    sink.on_node({n, NodeState::Lost, NodeState::Alive, now_us, now_us - s.last_seen_us, s.canopen_state});
  }
}

}  // namespace arnav::can
