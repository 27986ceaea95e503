#pragma once
// The host's security banner (issue 26; docs/protocol.md "Sealed bus", docs/overlay.md):
// from the messages the sealed bus dropped (seal::SealedLcm::on_drop live, seal::LogOpener
// on replay) it decides whether a camera frame carries a SECURITY banner and what it says.
//   - sealed messages rejected (forged, tampered, replayed, stale, malformed) within the
//     hold time before the frame: "SECURITY: bus messages rejected (5 s): forged 3, ...";
//   - an unsealed (plain LCM) message on the sealed bus within the hold time: "SECURITY:
//     unsealed messages on the sealed bus (5 s): 2, last on ARNAV_INPUT".
// The dropped messages themselves never reach the session: only their verdict and channel.
// Times are the session clock (CLOCK_MONOTONIC live, the log's clock on replay). A frame
// counts only the drops received at or before its own arrival (as the session's poses), so
// a replay shows the banners of the live run. Not thread-safe (the session holds its mutex).
#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "protocol/seal/channel_guard.hpp"

namespace arnav::host {

struct SecurityAlarmOptions {
  std::int64_t hold_us = 5'000'000;  // a banner stays this long after the last drop
  std::size_t max_entries = 65536;   // drops remembered (a flood beyond it: the window's counts are a lower bound)
};

// What was dropped in (now - hold, now].
struct SecurityWindow {
  seal::OpenCounters dropped;        // accepted stays 0
  std::string last_rejected_channel;  // the newest sealed-but-rejected message's channel
  std::string last_unsealed_channel;  // the newest unsealed message's channel
  std::uint64_t sealed_rejected() const { return dropped.forged + dropped.tampered + dropped.replayed + dropped.stale + dropped.malformed; }
  bool active() const { return dropped.dropped() > 0; }
};

class SecurityAlarm {
 public:
  explicit SecurityAlarm(SecurityAlarmOptions options = {});
  // A message the bus dropped on `channel`, received at now_us (calls in receive order).
  // Returns true when it starts an alert (nothing was dropped within the hold time before).
  // An Accepted verdict is not a drop: ignored (false).
  bool on_drop(seal::Verdict verdict, const std::string& channel, std::int64_t now_us);
  SecurityWindow window_at(std::int64_t now_us) const;
  // The frame's banner lines at now_us (none, one or two), as described above.
  std::vector<std::string> banners_at(std::int64_t now_us) const;
  // The newest drop's receive time (none yet: nullopt).
  std::optional<std::int64_t> last_drop_us() const {
    return entries_.empty() ? std::nullopt : std::optional<std::int64_t>(entries_.back().t_us);
  }
  // Every drop so far (not only the window's).
  const seal::OpenCounters& total() const { return total_; }
  std::int64_t hold_us() const { return options_.hold_us; }

 private:
  // One drop, with the running totals up to and including it: a window is the difference
  // of two entries (binary search on time), whatever the flood.
  struct Entry {
    std::int64_t t_us = 0;
    seal::OpenCounters running;
    std::uint32_t last_rejected = 0, last_unsealed = 0;  // channel ids + 1 (0: none yet)
  };
  std::uint32_t channel_id(const std::string& channel);

  SecurityAlarmOptions options_;
  std::deque<Entry> entries_;
  seal::OpenCounters base_;   // running totals before entries_.front() (forgotten entries)
  seal::OpenCounters total_;
  std::vector<std::string> channels_;                  // id - 1 -> name
  std::unordered_map<std::string, std::uint32_t> ids_;  // name -> id
};

}  // namespace arnav::host
