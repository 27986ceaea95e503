// The envelope and the receiver's verdicts: round trip, channel binding, every bit flip,
// replay window, age, wrong key, restarts, sender table (docs/protocol.md, "Sealed bus").
#include <gtest/gtest.h>

#include <cstring>

#include "protocol/seal/channel_guard.hpp"
#include "protocol/seal/envelope.hpp"

namespace arnav::seal {
namespace {

std::shared_ptr<const SessionKey> key_of(std::uint8_t fill) {
  std::array<std::uint8_t, kKeyBytes> b{};
  b.fill(fill);
  return std::make_shared<const SessionKey>(b);
}

std::vector<std::uint8_t> bytes_of(const std::string& s) { return {s.begin(), s.end()}; }

constexpr std::int64_t kNow = 1'700'000'000'000'000;

struct Fixture : ::testing::Test {
  std::shared_ptr<const SessionKey> key = key_of(7);
  Sealer sealer{key};
  Opener opener{key};
  std::vector<std::uint8_t> plain;
  std::vector<std::uint8_t> seal(const std::string& text, const std::string& channel = "ARNAV_POSE_scalpel", std::int64_t t = kNow) {
    std::vector<std::uint8_t> out;
    const auto p = bytes_of(text);
    sealer.seal(channel, p, t, out);
    return out;
  }
  Verdict open(const std::vector<std::uint8_t>& b, const std::string& channel = "ARNAV_POSE_scalpel", std::int64_t now = kNow + 1000) {
    return opener.open(channel, b, now, plain);
  }
};

TEST_F(Fixture, RoundTripGivesThePlaintextAndTheHeader) {
  const auto env = seal("pose bytes");
  EXPECT_EQ(env.size(), 10 + kOverheadBytes);
  EXPECT_TRUE(looks_sealed(env));
  // The plaintext does not appear in the envelope.
  const std::string text = "pose bytes";
  EXPECT_EQ(std::search(env.begin(), env.end(), text.begin(), text.end()), env.end());
  ASSERT_EQ(open(env), Verdict::Accepted);
  EXPECT_EQ(std::string(plain.begin(), plain.end()), "pose bytes");
  EXPECT_EQ(opener.last_header().counter, 1u);
  EXPECT_EQ(opener.last_header().sender, sealer.sender());
  EXPECT_EQ(opener.last_header().key_id, key->key_id());
  EXPECT_EQ(opener.counters().accepted, 1u);
}

TEST_F(Fixture, AnotherChannelDoesNotOpen) {
  const auto env = seal("pedal_cut pressed", "ARNAV_INPUT");
  ASSERT_EQ(open(env, "ARNAV_INPUT"), Verdict::Accepted);
  const auto env2 = seal("pedal_cut pressed", "ARNAV_INPUT");
  EXPECT_EQ(open(env2, "ARNAV_INPUT_STATE"), Verdict::Tampered);  // our key and sender: a moved copy
  EXPECT_TRUE(plain.empty());
}

TEST_F(Fixture, EveryBitFlipIsRejected) {
  const auto first = seal("a");  // makes the sender known, so authentic-looking damage reads as tampered
  ASSERT_EQ(open(first), Verdict::Accepted);
  const auto env = seal("X_RefTool of the scalpel");
  std::uint64_t rejected = 0;
  for (std::size_t byte = 0; byte < env.size(); ++byte) {
    for (int bit = 0; bit < 8; ++bit) {
      auto copy = env;
      copy[byte] ^= static_cast<std::uint8_t>(1u << bit);
      const Verdict v = open(copy);
      EXPECT_NE(v, Verdict::Accepted) << "byte " << byte << " bit " << bit;
      EXPECT_TRUE(plain.empty());
      rejected += v != Verdict::Accepted;
      // Flips in the ciphertext and tag, with the header intact, are tampering.
      if (byte >= kHeaderBytes) {
        EXPECT_EQ(v, Verdict::Tampered) << "byte " << byte;
      } else if (byte < 4) {
        EXPECT_EQ(v, Verdict::Unsealed);
      } else if (byte < 8) {
        EXPECT_EQ(v, Verdict::Malformed);
      }
    }
  }
  EXPECT_EQ(rejected, env.size() * 8);
  // The original still opens: the damaged copies did not advance the replay state.
  EXPECT_EQ(open(env), Verdict::Accepted);
}

TEST_F(Fixture, AnExactCopyIsAReplay) {
  const auto env = seal("pose");
  ASSERT_EQ(open(env), Verdict::Accepted);
  EXPECT_EQ(open(env), Verdict::Replayed);
  EXPECT_EQ(open(env), Verdict::Replayed);
  EXPECT_EQ(opener.counters().replayed, 2u);
}

TEST_F(Fixture, ReorderWithinTheWindowIsAcceptedOnceOlderIsReplayed) {
  std::vector<std::vector<std::uint8_t>> envs;
  for (int i = 0; i < 100; ++i) envs.push_back(seal(std::to_string(i)));
  ASSERT_EQ(open(envs[99]), Verdict::Accepted);                    // counter 100 first
  EXPECT_EQ(open(envs[99 - 63]), Verdict::Accepted);               // 63 behind: inside the window
  EXPECT_EQ(open(envs[99 - 63]), Verdict::Replayed);               // but once only
  EXPECT_EQ(open(envs[99 - 64]), Verdict::Replayed);               // 64 behind: outside, dropped
  EXPECT_EQ(open(envs[0]), Verdict::Replayed);
  const auto later = seal("m100");
  EXPECT_EQ(open(later), Verdict::Accepted);
}

TEST_F(Fixture, OldOrFutureMessagesAreStale) {
  EXPECT_EQ(open(seal("old", "C", kNow - 2'000'001), "C", kNow), Verdict::Stale);
  EXPECT_EQ(open(seal("future", "C", kNow + 2'000'001), "C", kNow), Verdict::Stale);
  EXPECT_EQ(open(seal("edge", "C", kNow - 2'000'000), "C", kNow), Verdict::Accepted);
  EXPECT_EQ(opener.counters().stale, 2u);
}

TEST_F(Fixture, TheWrongKeyIsForgedAndPlainMessagesAreUnsealed) {
  Sealer attacker(key_of(8));
  std::vector<std::uint8_t> env;
  attacker.seal("ARNAV_INPUT", bytes_of("pedal_cut pressed"), kNow, env);
  EXPECT_EQ(open(env, "ARNAV_INPUT"), Verdict::Forged);
  EXPECT_EQ(open(bytes_of("\x01\x02\x03\x04\x05\x06\x07\x08plain lcm"), "ARNAV_INPUT"), Verdict::Unsealed);
  EXPECT_EQ(open({}, "ARNAV_INPUT"), Verdict::Unsealed);
  auto truncated = seal("x");
  truncated.resize(kOverheadBytes - 1);
  EXPECT_EQ(open(truncated), Verdict::Malformed);
  const auto c = opener.counters();
  EXPECT_EQ(c.forged, 1u);
  EXPECT_EQ(c.unsealed, 2u);
  EXPECT_EQ(c.malformed, 1u);
  EXPECT_EQ(c.accepted, 0u);
  EXPECT_EQ(c.dropped(), 4u);
}

TEST_F(Fixture, ARestartedSenderHasANewIdAndIsAccepted) {
  ASSERT_EQ(open(seal("a")), Verdict::Accepted);
  ASSERT_EQ(open(seal("b")), Verdict::Accepted);
  Sealer restarted(key);
  EXPECT_NE(restarted.sender(), sealer.sender());
  std::vector<std::uint8_t> env;
  restarted.seal("ARNAV_POSE_scalpel", bytes_of("c"), kNow, env);  // counter 1 again, new nonce space
  EXPECT_EQ(open(env), Verdict::Accepted);
  EXPECT_EQ(opener.senders(), 2u);
}

TEST(Opener, ForgetsTheLeastRecentSenderWhenFull) {
  const auto key = key_of(3);
  Opener opener(key, OpenerOptions{2'000'000, 2});
  std::vector<std::uint8_t> plain, a1, b1, c1;
  Sealer a(key), b(key), c(key);
  a.seal("C", bytes_of("a"), kNow, a1);
  b.seal("C", bytes_of("b"), kNow, b1);
  c.seal("C", bytes_of("c"), kNow, c1);
  ASSERT_EQ(opener.open("C", a1, kNow, plain), Verdict::Accepted);
  ASSERT_EQ(opener.open("C", b1, kNow, plain), Verdict::Accepted);
  ASSERT_EQ(opener.open("C", c1, kNow, plain), Verdict::Accepted);  // a forgotten
  EXPECT_EQ(opener.senders(), 2u);
  EXPECT_EQ(opener.open("C", b1, kNow, plain), Verdict::Replayed);  // b still remembered
  // A forgotten sender's message inside the age limit opens again: the documented bound of
  // the sender table (docs/protocol.md); the age limit still ends it.
  EXPECT_EQ(opener.open("C", a1, kNow + 2'000'001, plain), Verdict::Stale);
  EXPECT_EQ(opener.open("C", a1, kNow, plain), Verdict::Accepted);
}

TEST(Envelope, ParseReportsWhyBytesAreNotAnEnvelope) {
  std::vector<std::uint8_t> b = {'A', 'R', 'N', 'S'};
  EXPECT_EQ(parse_envelope(b).error, ParseError::Truncated);
  b.resize(kOverheadBytes, 0);
  b[4] = 2;
  EXPECT_EQ(parse_envelope(b).error, ParseError::BadVersion);
  b[4] = kVersion;
  b[5] = kSuiteXChaCha20Poly1305;
  const auto r = parse_envelope(b);
  ASSERT_TRUE(r.envelope);
  EXPECT_EQ(r.envelope->plaintext_size(), 0u);
  EXPECT_EQ(parse_envelope(bytes_of("LCM fingerprint")).error, ParseError::NotSealed);
  EXPECT_STREQ(to_string(ParseError::Truncated), "envelope shorter than its header and tag");
}

}  // namespace
}  // namespace arnav::seal
