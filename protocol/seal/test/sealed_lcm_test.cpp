// SealedLcm on an in-process bus (memq): publish seals, subscribe opens once per message
// whatever the number of matching subscriptions, only accepted messages reach handlers;
// sealed logs open with the key and say clearly when the key or the mode is wrong.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <map>

#include "arnav/input_event_t.hpp"
#include "arnav/tool_pose_t.hpp"
#include "protocol/seal/log_opener.hpp"
#include "protocol/seal/sealed_lcm.hpp"
#include "protocol/testing/child_process.hpp"

namespace arnav::seal {
namespace {

namespace fs = std::filesystem;

std::shared_ptr<const SessionKey> key_of(std::uint8_t fill) {
  std::array<std::uint8_t, kKeyBytes> b{};
  b.fill(fill);
  return std::make_shared<const SessionKey>(b);
}

BusSecurity sealed_with(std::uint8_t fill) {
  BusSecurity s;
  s.key = key_of(fill);
  return s;
}

struct Sink {
  std::vector<tool_pose_t> poses, poses_too;
  std::vector<input_event_t> inputs;
  std::vector<std::size_t> raw_sizes;
  void pose(const lcm::ReceiveBuffer*, const std::string&, const tool_pose_t* m) { poses.push_back(*m); }
  void pose_too(const lcm::ReceiveBuffer*, const std::string&, const tool_pose_t* m) { poses_too.push_back(*m); }
  void input(const lcm::ReceiveBuffer*, const std::string&, const input_event_t* m) { inputs.push_back(*m); }
  void raw(const lcm::ReceiveBuffer* r, const std::string&) { raw_sizes.push_back(r->data_size); }
};

tool_pose_t pose_msg(const std::string& tool, std::int64_t seq) {
  tool_pose_t m{};
  m.tool_name = tool;
  m.frame_parent = "Ref";
  m.frame_child = "Tool";
  m.q_ParentChild_wxyz[0] = 1.0;
  m.p_ParentChild_mm[0] = 12.5;
  m.sequence = seq;
  return m;
}

void drain(SealedLcm& bus) {
  while (bus.handleTimeout(0) > 0) {
  }
}

TEST(SealedLcm, SealedMessagesReachEveryMatchingSubscriptionOnce) {
  SealedLcm bus("memq://", sealed_with(1));
  ASSERT_TRUE(bus.good());
  ASSERT_TRUE(bus.sealed());
  Sink sink;
  bus.subscribe("ARNAV_POSE_.*", &Sink::pose, &sink);
  bus.subscribe("ARNAV_POSE_scalpel", &Sink::pose_too, &sink);
  bus.subscribe("ARNAV_POSE_.*", &Sink::raw, &sink);
  for (int i = 1; i <= 3; ++i) {
    const tool_pose_t m = pose_msg("scalpel", i);
    ASSERT_EQ(bus.publish("ARNAV_POSE_scalpel", &m), 0);
  }
  drain(bus);
  ASSERT_EQ(sink.poses.size(), 3u);
  EXPECT_EQ(sink.poses_too.size(), 3u);
  EXPECT_EQ(sink.poses[2].sequence, 3);
  EXPECT_DOUBLE_EQ(sink.poses[0].p_ParentChild_mm[0], 12.5);
  ASSERT_EQ(sink.raw_sizes.size(), 3u);
  EXPECT_EQ(sink.raw_sizes[0], static_cast<std::size_t>(pose_msg("scalpel", 1).getEncodedSize()));  // opened bytes
  const BusCounters c = bus.counters();
  EXPECT_EQ(c.open.accepted, 3u);  // one verdict per message, not per subscription
  EXPECT_EQ(c.open.dropped(), 0u);
  EXPECT_NE(bus.status_line().find("accepted 3; dropped 0"), std::string::npos) << bus.status_line();
}

TEST(SealedLcm, ForgedUnsealedAndReplayedNeverReachAHandler) {
  SealedLcm bus("memq://", sealed_with(1));
  Sink sink;
  bus.subscribe("ARNAV_POSE_.*", &Sink::pose, &sink);
  bus.subscribe("ARNAV_POSE_pointer", &Sink::pose_too, &sink);  // a second match: still one verdict
  bus.subscribe("ARNAV_INPUT", &Sink::input, &sink);
  std::vector<std::pair<Verdict, std::string>> drops;  // what the host's banner hears
  bus.on_drop([&](Verdict v, const std::string& channel) { drops.emplace_back(v, channel); });
  // Plain LCM (what an attacker without the key sends, or a bench appliance with security off).
  input_event_t press{};
  press.input_name = "pedal_cut";
  press.state = input_event_t::STATE_PRESSED;
  bus.raw().publish("ARNAV_INPUT", &press);
  // Sealed with another key.
  {
    Sealer other(key_of(2));
    std::vector<std::uint8_t> bytes(static_cast<std::size_t>(press.getEncodedSize())), env;
    press.encode(bytes.data(), 0, press.getEncodedSize());
    other.seal("ARNAV_INPUT", bytes, ::time(nullptr) * 1000000LL, env);
    bus.raw().publish("ARNAV_INPUT", env.data(), static_cast<unsigned>(env.size()));
  }
  drain(bus);
  EXPECT_TRUE(sink.inputs.empty());
  // A genuine message, then its exact copy and a bit-flipped copy, both through the raw bus.
  struct Capture {
    std::vector<std::uint8_t> bytes;
    void raw(const lcm::ReceiveBuffer* r, const std::string&) {
      const auto* p = static_cast<const std::uint8_t*>(r->data);
      bytes.assign(p, p + r->data_size);
    }
  } capture;
  lcm::LCM& raw = bus.raw();
  raw.subscribe("ARNAV_POSE_pointer", &Capture::raw, &capture);
  const tool_pose_t m = pose_msg("pointer", 1);
  bus.publish("ARNAV_POSE_pointer", &m);
  drain(bus);
  ASSERT_EQ(sink.poses.size(), 1u);
  ASSERT_TRUE(looks_sealed(capture.bytes));
  const auto copy = capture.bytes;
  raw.publish("ARNAV_POSE_pointer", copy.data(), static_cast<unsigned>(copy.size()));
  auto flipped = copy;
  flipped[flipped.size() - 20] ^= 0x10;
  raw.publish("ARNAV_POSE_pointer", flipped.data(), static_cast<unsigned>(flipped.size()));
  drain(bus);
  EXPECT_EQ(sink.poses.size(), 1u);
  const OpenCounters c = bus.counters().open;
  EXPECT_EQ(c.accepted, 1u);
  EXPECT_EQ(c.unsealed, 1u);
  EXPECT_EQ(c.forged, 1u);
  EXPECT_EQ(c.replayed, 1u);
  EXPECT_EQ(c.tampered, 1u);
  EXPECT_NE(bus.status_line().find("SECURITY ALERT: 4 messages rejected"), std::string::npos) << bus.status_line();
  const std::vector<std::pair<Verdict, std::string>> expected = {{Verdict::Unsealed, "ARNAV_INPUT"},
                                                                 {Verdict::Forged, "ARNAV_INPUT"},
                                                                 {Verdict::Replayed, "ARNAV_POSE_pointer"},
                                                                 {Verdict::Tampered, "ARNAV_POSE_pointer"}};
  EXPECT_EQ(drops, expected);
  EXPECT_EQ(sink.poses_too.size(), 1u);
  // The audit: one sender (this instance), accepted once, nothing twice.
  const BusCounters bc = bus.counters();
  ASSERT_EQ(bc.senders.size(), 1u);
  EXPECT_EQ(bc.senders[0].accepted, 1u);
  EXPECT_EQ(bc.senders[0].highest, 1u);
  EXPECT_EQ(bc.senders[0].accepted_twice, 0u);
}

TEST(SealedLcm, SendersAreAnnouncedAndTheHostsAuditListsOnlyThem) {
  std::vector<std::string> announced;
  SealedLcm::announce_senders([&](const std::string& s) { announced.push_back(s); });
  SealedLcm receiver("memq://", sealed_with(1));
  SealedLcm off("memq://", BusSecurity::off());  // not a sender of the sealed bus: not announced
  SealedLcm::announce_senders(nullptr);
  ASSERT_EQ(announced.size(), 1u);
  EXPECT_EQ(announced[0].size(), 16u);
  Sink sink;
  receiver.subscribe("ARNAV_POSE_.*", &Sink::pose, &sink);
  // Two publishers of the same key, through the receiver's memq bus (their envelopes sealed by their own Sealers).
  Sealer a(key_of(1)), b(key_of(1));
  const tool_pose_t m = pose_msg("pointer", 1);
  std::vector<std::uint8_t> plain(static_cast<std::size_t>(m.getEncodedSize())), env;
  m.encode(plain.data(), 0, m.getEncodedSize());
  const auto send = [&](Sealer& s) {
    s.seal("ARNAV_POSE_pointer", plain, ::time(nullptr) * 1000000LL, env);
    receiver.raw().publish("ARNAV_POSE_pointer", env.data(), static_cast<unsigned>(env.size()));
  };
  for (int i = 0; i < 5; ++i) send(a);
  for (int i = 0; i < 2; ++i) send(b);
  drain(receiver);
  EXPECT_EQ(sink.poses.size(), 7u);
  std::map<std::string, SenderTally> by_id;
  for (const auto& t : receiver.counters().senders) by_id[t.sender] = t;
  ASSERT_EQ(by_id.size(), 2u);
  EXPECT_EQ(by_id.at(sender_hex(a.sender())).accepted, 5u);
  EXPECT_EQ(by_id.at(sender_hex(a.sender())).highest, 5u);
  EXPECT_EQ(by_id.at(sender_hex(b.sender())).accepted, 2u);
  EXPECT_EQ(by_id.at(sender_hex(b.sender())).accepted_twice, 0u);
}

TEST(SealedLcm, OffPassesPlainMessagesAndSetsSealedOnesAside) {
  SealedLcm bus("memq://", BusSecurity::off());
  EXPECT_FALSE(bus.sealed());
  Sink sink;
  bus.subscribe("ARNAV_POSE_.*", &Sink::pose, &sink);
  const tool_pose_t m = pose_msg("pointer", 1);
  bus.publish("ARNAV_POSE_pointer", &m);
  Sealer sealer(key_of(1));
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(m.getEncodedSize())), env;
  m.encode(bytes.data(), 0, m.getEncodedSize());
  sealer.seal("ARNAV_POSE_pointer", bytes, 0, env);
  bus.raw().publish("ARNAV_POSE_pointer", env.data(), static_cast<unsigned>(env.size()));
  drain(bus);
  EXPECT_EQ(sink.poses.size(), 1u);
  EXPECT_EQ(bus.counters().sealed_on_off_bus, 1u);
  EXPECT_NE(bus.status_line().find("security: OFF"), std::string::npos);
  EXPECT_NE(bus.status_line().find("1 sealed messages ignored"), std::string::npos);
}

// A log as lcm-logger writes it: the wire bytes with the receive time.
struct LogFixture : ::testing::Test {
  fs::path dir = fs::temp_directory_path() / ("seal_log_test_" + std::to_string(::getpid()));
  std::string log_path = (dir / "session.lcmlog").string();
  std::int64_t t0 = 1'700'000'000'000'000;
  void SetUp() override { fs::create_directories(dir); }
  void TearDown() override { fs::remove_all(dir); }
  // n sealed poses (key `fill`), then an exact copy of the first one (a replay in the log).
  void write_sealed(std::uint8_t fill, int n) {
    lcm::LogFile log(log_path, "w");
    Sealer sealer(key_of(fill));
    std::vector<std::uint8_t> first;
    for (int i = 0; i < n; ++i) {
      const tool_pose_t m = pose_msg("scalpel", i + 1);
      std::vector<std::uint8_t> bytes(static_cast<std::size_t>(m.getEncodedSize())), env;
      m.encode(bytes.data(), 0, m.getEncodedSize());
      sealer.seal("ARNAV_POSE_scalpel", bytes, t0 + i * 1000, env);
      if (i == 0) first = env;
      write(log, "ARNAV_POSE_scalpel", env, t0 + i * 1000 + 300);
    }
    write(log, "ARNAV_POSE_scalpel", first, t0 + n * 1000);
  }
  static void write(lcm::LogFile& log, const std::string& channel, std::vector<std::uint8_t>& bytes, std::int64_t t) {
    lcm::LogEvent ev{};
    ev.timestamp = t;
    ev.channel = channel;
    ev.datalen = static_cast<std::int32_t>(bytes.size());
    ev.data = bytes.data();
    log.writeEvent(&ev);
  }
  OpenCounters read_all(LogOpener& opener) {
    lcm::LogFile log(log_path, "r");
    while (const lcm::LogEvent* ev = log.readNextEvent()) opener.open(*ev);
    return opener.counters();
  }
};

TEST_F(LogFixture, ASealedLogOpensWithItsKeyAtItsOwnTime) {
  write_sealed(5, 10);
  LogOpener opener(sealed_with(5));
  const OpenCounters c = read_all(opener);
  EXPECT_EQ(c.accepted, 10u);  // the log is years "old": its own receive times are the clock
  EXPECT_EQ(c.replayed, 1u);
  EXPECT_EQ(opener.problem(log_path), "");
}

TEST_F(LogFixture, WrongKeyOldLogAndNoKeyAreNamed) {
  write_sealed(5, 3);
  LogOpener wrong(sealed_with(6));
  read_all(wrong);
  const std::string p = wrong.problem(log_path);
  EXPECT_NE(p.find(log_path + ": wrong key: the log was sealed with key id " + key_of(5)->key_id_hex()), std::string::npos) << p;
  LogOpener none(BusSecurity::off());
  read_all(none);
  EXPECT_NE(none.problem(log_path).find("the log is sealed"), std::string::npos) << none.problem(log_path);

  {
    lcm::LogFile log(log_path, "w");
    const tool_pose_t m = pose_msg("scalpel", 1);
    std::vector<std::uint8_t> bytes(static_cast<std::size_t>(m.getEncodedSize()));
    m.encode(bytes.data(), 0, m.getEncodedSize());
    write(log, "ARNAV_POSE_scalpel", bytes, t0);
  }
  LogOpener keyed(sealed_with(5));
  read_all(keyed);
  EXPECT_NE(keyed.problem(log_path).find("the log is not sealed"), std::string::npos) << keyed.problem(log_path);
  LogOpener plain(BusSecurity::off());
  EXPECT_EQ(read_all(plain).accepted, 1u);
}

TEST_F(LogFixture, DecodeToolShowsTheMessagesAndNamesTheWrongKey) {
  write_sealed(5, 4);
  const std::string key_path = (dir / "bus.key").string();
  {
    std::array<std::uint8_t, kKeyBytes> b{};
    b.fill(5);
    std::FILE* f = std::fopen(key_path.c_str(), "wb");
    ASSERT_NE(f, nullptr);
    std::fwrite(b.data(), 1, b.size(), f);
    std::fclose(f);
    fs::permissions(key_path, fs::perms::owner_read | fs::perms::owner_write);
  }
  const std::string exe = arnav::testing::binary_path("protocol/seal/arnav-lcm-decode");
  auto r = arnav::testing::run_command(exe + " " + log_path + " --key " + key_path);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("ARNAV_POSE_scalpel accepted sender"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("tool_pose_t scalpel X_RefTool status 0 p_mm (12.5, 0.0, 0.0) seq 4"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("ARNAV_POSE_scalpel replayed"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("5 messages (0 LCM self-test messages skipped): accepted 4; dropped 1"), std::string::npos) << r.output;
  r = arnav::testing::run_command(exe + " " + log_path + " --security off");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("the log is sealed"), std::string::npos) << r.output;
  r = arnav::testing::run_command(exe + " " + log_path);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("give --key FILE"), std::string::npos) << r.output;
  fs::permissions(key_path, fs::perms::group_read, fs::perm_options::add);
  r = arnav::testing::run_command(exe + " " + log_path + " --key " + key_path);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("mode 640"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace arnav::seal
