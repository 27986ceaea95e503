#pragma once
// Named inputs of the appliance's CAN path (foot pedal, instrument buttons) as the session
// sees them: changes on ARNAV_INPUT and the periodic snapshots on ARNAV_INPUT_STATE
// (input_event_t, docs/can.md). A held input counts only while its state is fresh: a lost
// release (UDP) is re-synced by the next snapshot, and when neither a change nor a snapshot
// arrived within the binding's limit the input reads as released ("stale": cutting is
// disarmed). Press edges (released -> pressed, from a change or a snapshot that shows a
// press the session missed) are kept in order for the actions that take them (accept).
// Clock: the session clock (now_us), like poses.
#include <algorithm>
#include <cstdint>
#include <deque>
#include <map>
#include <string>
#include <vector>

#include "arnav/input_event_t.hpp"

namespace arnav::host {

struct InputLevel {
  bool known = false;            // a change or a snapshot has been seen
  bool pressed = false;
  std::int64_t last_seen_us = -1;  // newest change or snapshot (session clock)
  std::int64_t sequence = -1;    // newest change number seen
  std::int64_t presses = 0;
  std::int64_t resyncs = 0;      // snapshots that corrected the level (a change was lost)
  std::int8_t last_cause = -1;
  // Level changes on the appliance's clock (decided_time_mono_us), oldest first, the last
  // kHistory: what the level was when the tracker measured a tool (pressed_at).
  std::deque<std::pair<std::int64_t, bool>> changes_device_us;
};

enum class HeldState { kHeld, kReleased, kStale, kNeverSeen };

class InputTracker {
 public:
  // Returns true when this message is a press edge of its input.
  bool on_input(const input_event_t& msg, std::int64_t now_us);
  // Held with a state no older than stale_after_ms at now_us.
  HeldState held(const std::string& input, double stale_after_ms, std::int64_t now_us) const;
  const InputLevel* level(const std::string& input) const;
  // The level at a device time (the appliance's clock): the newest change decided at or
  // before it (false before the first). Freshness is held()'s business.
  bool pressed_at(const std::string& input, std::int64_t device_time_us) const;
  const std::map<std::string, InputLevel>& levels() const { return levels_; }
  std::int64_t messages() const { return messages_; }

 private:
  std::map<std::string, InputLevel> levels_;
  std::int64_t messages_ = 0;
};

}  // namespace arnav::host
