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
    if (parsed.envelope) foreign_key_ids_.insert(parsed.envelope->header.key_id);
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
    std::string ids;
    for (const auto id : foreign_key_ids_) ids += (ids.empty() ? "" : ", ") + key_id_hex(id);
    return log_path + ": wrong key: the log was sealed with key id " + ids + ", the key given has key id " + security_.key->key_id_hex() +
           ": give the key the session was recorded with";
  }
  if (counters_.unsealed > 0 && counters_.dropped() == counters_.unsealed)
    return log_path + ": the log is not sealed (an old log, or one recorded with security: off): read it with 'security: off' (or --security off)";
  if (counters_.dropped() > 0) return log_path + ": no message of the log could be opened: " + format_counters(counters_);
  return "";
}

}  // namespace arnav::seal
