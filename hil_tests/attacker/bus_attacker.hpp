#pragma once
// The bench's attacker (hil_tests only): it has the network, not the key. Each injection is
// one of the kinds below, in turn; it counts what it sent by the verdict a receiver with the
// key must reach, so a test compares the receiver's counters with these.
#include <lcm/lcm-cpp.hpp>

#include <cstdint>
#include <deque>
#include <random>
#include <string>
#include <unordered_set>
#include <vector>

#include <nlohmann/json.hpp>

#include "protocol/seal/channel_guard.hpp"

namespace arnav::hil {

struct AttackPlan {
  std::string tool = "liver_marker";  // forged poses of this tool (and of "scalpel")
  std::string camera = "bench";       // forged frames on ARNAV_FRAME_<camera>
  std::string earlier_log;            // sealed messages of an earlier session (stale), optional
  std::size_t frame_bytes = 4000;     // forged frame payload
};

struct AttackCounts {
  std::uint64_t unsealed = 0;  // plain LCM: forged poses, pedal presses, frames
  std::uint64_t forged = 0;    // the same sealed with the attacker's own key
  std::uint64_t replayed = 0;  // captured sealed messages sent again, unchanged
  std::uint64_t tampered = 0;  // captured ones with a ciphertext/tag bit flipped, or moved to another channel
  std::uint64_t stale = 0;     // an earlier session's sealed messages
  std::uint64_t total() const { return unsealed + forged + replayed + tampered + stale; }
  nlohmann::json json() const;
};

class BusAttacker {
 public:
  BusAttacker(lcm::LCM& bus, AttackPlan plan);
  // Call with the bus's received messages (subscribed raw to ".*").
  void on_message(const lcm::ReceiveBuffer* rbuf, const std::string& channel);
  // One injection (the next kind in turn that can be made now); false when none could.
  bool inject();
  const AttackCounts& counts() const { return counts_; }
  std::size_t captured() const { return captured_.size(); }

 private:
  struct Captured {
    std::string channel;
    std::vector<std::uint8_t> bytes;
  };
  void send(const std::string& channel, const std::vector<std::uint8_t>& bytes);
  template <class Msg>
  std::vector<std::uint8_t> encode(const Msg& m);
  std::vector<std::uint8_t> forged_pose(const std::string& tool);
  std::vector<std::uint8_t> forged_pedal();
  std::vector<std::uint8_t> forged_frame();
  std::vector<std::uint8_t> seal_with_own_key(const std::string& channel, const std::vector<std::uint8_t>& plain);

  lcm::LCM& bus_;
  AttackPlan plan_;
  std::mt19937_64 rng_{0x5eed};
  seal::Sealer own_;  // a key the receivers do not have
  std::deque<Captured> captured_;
  std::unordered_set<std::string> sent_;  // our own messages come back on the bus: not captured
  std::vector<Captured> earlier_;
  std::size_t earlier_next_ = 0;
  unsigned turn_ = 0;
  AttackCounts counts_;
};

}  // namespace arnav::hil
