#pragma once
// Sender and receiver sides of the sealed bus (docs/protocol.md, "Sealed bus").
// Sealer: one per publishing LCM instance; a fresh random sender id per construction (a
// restarted sender is a new sender), a counter from 1. Opener: one per receiving LCM
// instance; classifies every message and keeps per-sender replay state.
#include <cstdint>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "protocol/seal/envelope.hpp"
#include "protocol/seal/key.hpp"

namespace arnav::seal {

class Sealer {
 public:
  explicit Sealer(std::shared_ptr<const SessionKey> key);
  // Seals one LCM message for channel into out (its capacity is reused). Not thread-safe:
  // callers that publish from several threads serialise (SealedLcm does).
  void seal(std::string_view channel, std::span<const std::uint8_t> plaintext, std::int64_t time_wall_us, std::vector<std::uint8_t>& out);
  const SenderId& sender() const { return header_.sender; }
  std::uint64_t sent() const { return header_.counter; }

 private:
  std::shared_ptr<const SessionKey> key_;
  EnvelopeHeader header_;
};

// What a receiver did with one message. Only Accepted reaches a handler.
enum class Verdict {
  Accepted,
  Unsealed,   // no envelope: a plain LCM message (an attacker without the key, or a sender with security: off)
  Malformed,  // envelope magic but a bad version, suite or length
  Forged,     // does not authenticate, and does not look like a damaged copy of a message of ours
  Tampered,   // does not authenticate, but carries our key id and a sender we have accepted from:
              // a sealed message with bits changed (ciphertext, tag, header or moved channel)
  Replayed,   // authentic, but its counter was seen already or is older than the reorder window
  Stale,      // authentic and never seen, but sealed more than max_age from the receive time (either way)
};
const char* to_string(Verdict v);

struct OpenCounters {
  std::uint64_t accepted = 0, unsealed = 0, malformed = 0, forged = 0, tampered = 0, replayed = 0, stale = 0;
  std::uint64_t dropped() const { return unsealed + malformed + forged + tampered + replayed + stale; }
  void add(Verdict v);
};

// One line: "accepted N; dropped M (forged a, tampered b, replayed c, stale d, unsealed e, malformed f)".
std::string format_counters(const OpenCounters& c);

struct OpenerOptions {
  std::int64_t max_age_us = 2'000'000;  // sealed-to-received age (and clock skew) accepted
  std::size_t max_senders = 64;         // senders remembered (least recently accepted forgotten first)
};

class Opener {
 public:
  static constexpr std::uint64_t kReorderWindow = 64;  // counters this far below the newest still accepted once

  Opener(std::shared_ptr<const SessionKey> key, OpenerOptions options = {});
  // Classifies bytes received on channel at now_wall_us (the receive time: LCM's recv_utime
  // live, the log's timestamp on replay). On Accepted, plain holds the LCM message.
  Verdict open(std::string_view channel, std::span<const std::uint8_t> bytes, std::int64_t now_wall_us, std::vector<std::uint8_t>& plain);
  // The header of the last message that parsed (for tools that print it).
  const EnvelopeHeader& last_header() const { return last_header_; }
  const OpenCounters& counters() const { return counters_; }
  std::size_t senders() const { return senders_.size(); }
  const SessionKey& key() const { return *key_; }

 private:
  struct SenderState {
    std::uint64_t highest = 0;
    std::uint64_t seen_bits = 0;  // bit i: counter highest - i seen
    std::uint64_t last_use = 0;
  };
  Verdict classify(std::string_view channel, std::span<const std::uint8_t> bytes, std::int64_t now_wall_us, std::vector<std::uint8_t>& plain);
  Verdict check_fresh(const EnvelopeHeader& h, std::int64_t now_wall_us);

  std::shared_ptr<const SessionKey> key_;
  OpenerOptions options_;
  std::map<SenderId, SenderState> senders_;
  std::uint64_t use_clock_ = 0;
  OpenCounters counters_;
  EnvelopeHeader last_header_;
};

}  // namespace arnav::seal
