#pragma once
// Opening an lcm-logger log of a sealed bus (arnav-host --replay, arnav-lcm-decode, the
// bench's log readers). The logger records the sealed bytes as they were on the wire; each
// event is opened with the key, the log's receive timestamp standing in for "now" (so the
// age check holds against the time of recording, and a replayed message in the log is still
// a replay). With security off the events pass as they are and sealed ones are counted.
#include <lcm/lcm-cpp.hpp>

#include <cstdint>
#include <optional>
#include <map>
#include <span>
#include <string>
#include <vector>

#include "protocol/seal/channel_guard.hpp"
#include "protocol/seal/security_config.hpp"

namespace arnav::seal {

class LogOpener {
 public:
  explicit LogOpener(BusSecurity security);
  // The event's LCM message, or nothing when it is dropped (counted).
  std::optional<std::span<const std::uint8_t>> open(const lcm::LogEvent& event);
  Verdict last_verdict() const { return last_; }
  const OpenCounters& counters() const { return counters_; }
  std::uint64_t sealed_without_key() const { return sealed_without_key_; }
  // When nothing could be opened: why, and what to do (empty when the log opened).
  std::string problem(const std::string& log_path) const;
  const BusSecurity& security() const { return security_; }
  const Opener* opener() const { return opener_ ? &*opener_ : nullptr; }

 private:
  BusSecurity security_;
  std::optional<Opener> opener_;
  std::vector<std::uint8_t> plain_;
  OpenCounters counters_;
  Verdict last_ = Verdict::Unsealed;
  std::uint64_t sealed_without_key_ = 0;
  std::map<std::uint32_t, std::uint64_t> foreign_key_ids_;  // key id -> messages
};

}  // namespace arnav::seal
