#include "host/app/input_state.hpp"

#include <algorithm>

namespace arnav::host {

bool InputTracker::on_input(const input_event_t& msg, std::int64_t now_us) {
  ++messages_;
  InputLevel& l = levels_[msg.input_name];
  const bool pressed = msg.state == input_event_t::STATE_PRESSED;
  const bool snapshot = msg.cause == input_event_t::CAUSE_STATE;
  // A change older than one already applied (reordered datagram) only refreshes the time.
  if (!snapshot && l.sequence >= 0 && msg.sequence < l.sequence) {
    l.last_seen_us = std::max(l.last_seen_us, now_us);
    return false;
  }
  // A snapshot that shows a press the session missed counts; the first snapshot of an input
  // already held when the session started does not (no accept from a button held at start).
  const bool edge = pressed && (snapshot ? (l.known && !l.pressed) : (!l.known || !l.pressed));
  if (snapshot && l.known && l.pressed != pressed) ++l.resyncs;
  if (!l.known || l.pressed != pressed) {
    // Forced releases (device or link lost) carry no frame time: the decision's time.
    const std::int64_t t = msg.decided_time_mono_us > 0 ? msg.decided_time_mono_us : msg.publish_time_mono_us;
    l.changes_device_us.emplace_back(t, pressed);
    constexpr std::size_t kHistory = 256;
    if (l.changes_device_us.size() > kHistory) l.changes_device_us.pop_front();
  }
  l.known = true;
  l.pressed = pressed;
  l.last_seen_us = std::max(l.last_seen_us, now_us);
  l.sequence = std::max(l.sequence, msg.sequence);
  l.last_cause = msg.cause;
  if (edge) ++l.presses;
  return edge;
}

HeldState InputTracker::held(const std::string& input, double stale_after_ms, std::int64_t now_us) const {
  const auto it = levels_.find(input);
  if (it == levels_.end() || !it->second.known) return HeldState::kNeverSeen;
  if (static_cast<double>(now_us - it->second.last_seen_us) > stale_after_ms * 1000.0) return HeldState::kStale;
  return it->second.pressed ? HeldState::kHeld : HeldState::kReleased;
}

const InputLevel* InputTracker::level(const std::string& input) const {
  const auto it = levels_.find(input);
  return it == levels_.end() ? nullptr : &it->second;
}

bool InputTracker::pressed_at(const std::string& input, std::int64_t device_time_us) const {
  const auto it = levels_.find(input);
  if (it == levels_.end()) return false;
  bool pressed = false;
  for (const auto& [t, p] : it->second.changes_device_us) {
    if (t > device_time_us) break;
    pressed = p;
  }
  return pressed;
}

}  // namespace arnav::host
