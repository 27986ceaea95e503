#include "protocol/seal/log_opener.hpp"

#include <algorithm>

namespace arnav::seal {

LogOpener::LogOpener(BusSecurity security) : security_(std::move(security)) {
  if (security_.key) {
    // A log is read long after it was recorded: the age is checked against the recording's
    // own receive time, with the live tolerance.
    opener_.emplace(security_.key, security_.options);
  }
}

std::optional<std::span<const std::uint8_t>> LogOpener::open(const lcm::LogEvent& event) {
  const std::span<const std::uint8_t> bytes(static_cast<const std::uint8_t*>(event.data), static_cast<std::size_t>(std::max(0, event.datalen)));
  if (!opener_) {
    if (looks_sealed(bytes)) {
      ++sealed_without_key_;
      last_ = Verdict::Malformed;
      return std::nullopt;
    }
    ++counters_.accepted;
    last_ = Verdict::Accepted;
    return bytes;
  }
  last_ = opener_->open(event.channel, bytes, event.timestamp, plain_);
  counters_ = opener_->counters();
  if (last_ == Verdict::Forged && opener_->last_header().key_id != security_.key->key_id()) {
    const auto parsed = parse_envelope(bytes);
    if (parsed.envelope) ++foreign_key_ids_[parsed.envelope->header.key_id];
  }
  if (last_ != Verdict::Accepted) return std::nullopt;
  return std::span<const std::uint8_t>(plain_.data(), plain_.size());
}

std::string LogOpener::problem(const std::string& log_path) const {
  if (counters_.accepted > 0) return "";
  if (!opener_) {
    if (sealed_without_key_ > 0)
      return log_path + ": the log is sealed (" + std::to_string(sealed_without_key_) +
             " sealed messages) and security is off: give the bus key (security: {key_file: PATH}, or --key PATH)";
    return "";
  }
  if (!foreign_key_ids_.empty() && counters_.forged > 0) {
    // The key most messages were sealed with first; others (an attacker's, another OR's) after it.
    std::vector<std::pair<std::uint64_t, std::uint32_t>> by_count;
    for (const auto& [id, n] : foreign_key_ids_) by_count.emplace_back(n, id);
    std::sort(by_count.rbegin(), by_count.rend());
    std::string others;
    for (std::size_t i = 1; i < by_count.size(); ++i)
      others += (others.empty() ? " (also " : ", ") + key_id_hex(by_count[i].second) + ": " + std::to_string(by_count[i].first);
    if (!others.empty()) others += ")";
    return log_path + ": wrong key: the log was sealed with key id " + key_id_hex(by_count[0].second) + " (" + std::to_string(by_count[0].first) +
           " messages)" + others + ", the key given has key id " + security_.key->key_id_hex() + ": give the key the session was recorded with";
  }
  if (counters_.unsealed > 0 && counters_.dropped() == counters_.unsealed)
    return log_path + ": the log is not sealed (an old log, or one recorded with security: off): read it with 'security: off' (or --security off)";
  if (counters_.dropped() > 0) return log_path + ": no message of the log could be opened: " + format_counters(counters_);
  return "";
}

}  // namespace arnav::seal
