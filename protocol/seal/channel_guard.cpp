#include "protocol/seal/channel_guard.hpp"

#include <algorithm>

namespace arnav::seal {

Sealer::Sealer(std::shared_ptr<const SessionKey> key) : key_(std::move(key)) {
  header_.key_id = key_->key_id();
  header_.sender = random_sender_id();
}

void Sealer::seal(std::string_view channel, std::span<const std::uint8_t> plaintext, std::int64_t time_wall_us, std::vector<std::uint8_t>& out) {
  ++header_.counter;  // from 1; 2^64 messages never wrap in practice (a restart takes a new id)
  header_.time_wall_us = time_wall_us;
  seal_message(*key_, header_, channel, plaintext, out);
}

const char* to_string(Verdict v) {
  switch (v) {
    case Verdict::Accepted: return "accepted";
    case Verdict::Unsealed: return "unsealed";
    case Verdict::Malformed: return "malformed";
    case Verdict::Forged: return "forged";
    case Verdict::Tampered: return "tampered";
    case Verdict::Replayed: return "replayed";
    case Verdict::Stale: return "stale";
  }
  return "?";
}

void OpenCounters::add(Verdict v) {
  switch (v) {
    case Verdict::Accepted: ++accepted; break;
    case Verdict::Unsealed: ++unsealed; break;
    case Verdict::Malformed: ++malformed; break;
    case Verdict::Forged: ++forged; break;
    case Verdict::Tampered: ++tampered; break;
    case Verdict::Replayed: ++replayed; break;
    case Verdict::Stale: ++stale; break;
  }
}

std::string format_counters(const OpenCounters& c) {
  return "accepted " + std::to_string(c.accepted) + "; dropped " + std::to_string(c.dropped()) + " (forged " + std::to_string(c.forged) +
         ", tampered " + std::to_string(c.tampered) + ", replayed " + std::to_string(c.replayed) + ", stale " + std::to_string(c.stale) +
         ", unsealed " + std::to_string(c.unsealed) + ", malformed " + std::to_string(c.malformed) + ")";
}

Opener::Opener(std::shared_ptr<const SessionKey> key, OpenerOptions options) : key_(std::move(key)), options_(options) {}

Verdict Opener::open(std::string_view channel, std::span<const std::uint8_t> bytes, std::int64_t now_wall_us, std::vector<std::uint8_t>& plain) {
  const Verdict v = classify(channel, bytes, now_wall_us, plain);
  counters_.add(v);
  if (v != Verdict::Accepted) plain.clear();
  return v;
}

Verdict Opener::classify(std::string_view channel, std::span<const std::uint8_t> bytes, std::int64_t now_wall_us, std::vector<std::uint8_t>& plain) {
  const ParseResult parsed = parse_envelope(bytes);
  if (!parsed.envelope) return parsed.error == ParseError::NotSealed ? Verdict::Unsealed : Verdict::Malformed;
  const ParsedEnvelope& e = *parsed.envelope;
  last_header_ = e.header;
  if (!open_message(*key_, e, channel, plain)) {
    const bool ours = e.header.key_id == key_->key_id() && senders_.count(e.header.sender) > 0;
    return ours ? Verdict::Tampered : Verdict::Forged;
  }
  return check_fresh(e.header, now_wall_us);
}

// Authentic: replay window per sender (IPsec/DTLS style sliding bitmap), then age.
Verdict Opener::check_fresh(const EnvelopeHeader& h, std::int64_t now_wall_us) {
  auto it = senders_.find(h.sender);
  if (it != senders_.end()) {
    SenderState& s = it->second;
    if (h.counter <= s.highest) {
      const std::uint64_t back = s.highest - h.counter;
      if (back >= kReorderWindow || (s.seen_bits >> back) & 1u) return Verdict::Replayed;
    }
  }
  const std::int64_t age_us = now_wall_us - h.time_wall_us;
  if (age_us > options_.max_age_us || age_us < -options_.max_age_us) return Verdict::Stale;
  if (it == senders_.end()) {
    if (senders_.size() >= options_.max_senders) {
      auto oldest = std::min_element(senders_.begin(), senders_.end(),
                                     [](const auto& a, const auto& b) { return a.second.last_use < b.second.last_use; });
      senders_.erase(oldest);
    }
    it = senders_.emplace(h.sender, SenderState{h.counter, 1u, 0}).first;
  } else {
    SenderState& s = it->second;
    if (h.counter > s.highest) {
      const std::uint64_t shift = h.counter - s.highest;
      s.seen_bits = shift >= 64 ? 1u : (s.seen_bits << shift) | 1u;
      s.highest = h.counter;
    } else {
      s.seen_bits |= std::uint64_t{1} << (s.highest - h.counter);
    }
  }
  it->second.last_use = ++use_clock_;
  return Verdict::Accepted;
}

}  // namespace arnav::seal
