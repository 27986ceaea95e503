// The sealed bus into the navigation session (issue 26; docs/overlay.md, "Security banner"):
// arnav-host's own wiring (bus_handlers.hpp) on LCM's in-process bus, and arnav-host
// --replay on a sealed log. Forged, tampered, replayed and unsealed messages never reach
// the tracker, the overlay, the inputs or the model (no scalpel, no blade distance, no cut
// trace, no pedal press, the reference's count unchanged); the frames after them carry the
// SECURITY banner and flags until the hold time has passed; the alert's start and end are
// said once; a replay of the log shows the banner on the same frames.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <sstream>

#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>
#include <sodium.h>

#include "host/app/bus_handlers.hpp"
#include "host/app/test/session_test_util.hpp"
#include "protocol/channels.hpp"
#include "protocol/seal/key.hpp"
#include "protocol/seal/sealed_lcm.hpp"

namespace arnav::host {
namespace {

using namespace arnav::host::test;

constexpr std::int64_t kS = 1'000'000;

std::shared_ptr<const seal::SessionKey> random_key() {
  std::array<std::uint8_t, seal::kKeyBytes> b{};
  seal::init_sodium();
  randombytes_buf(b.data(), b.size());
  return std::make_shared<const seal::SessionKey>(b);
}

// The coarse-liver session of session_test_util, sealed with FOLDER/bus.key; tools stay
// fresh for a minute (the in-process test renders on the real clock on a busy machine).
std::string sealed_session(const SessionFolder& f) {
  seal::write_new_key((f.dir / "bus.key").string());
  return f.write("sealed.yaml", "arnav_session_version: 1\n"
                                "lcm_url: \"memq://\"\n"
                                "scene: " + data_dir() + "/liver/liver_coarse.scene.yaml\n"
                                "registration: X_RefModel.yaml\n"
                                "tools:\n"
                                "  reference: {name: liver_marker, stale_after_ms: 60000}\n"
                                "  scalpel: {name: scalpel, stale_after_ms: 60000, blade: {tip_mm: [0, 0, 0], heel_mm: [0, 0, 30]}}\n"
                                "camera: {name: cam0, intrinsics: camera.yaml, pose_from: reference, stale_after_ms: 60000}\n"
                                "model: {rate_hz: 60, gravity: false}\n"
                                "overlay: {margin_mm: 5, warn_mm: 5}\n"
                                "security: {key_file: bus.key}\n");
}

template <class Msg>
std::vector<std::uint8_t> encoded(const Msg& m) {
  std::vector<std::uint8_t> b(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(b.data(), 0, m.getEncodedSize());
  return b;
}

std::int64_t wall_now_us() {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
}

// The scalpel's tip on the tumour centre (Ref origin, test_X_RefModel): accepted, it would
// give a blade-to-margin distance and a cut trace.
tool_pose_t scalpel_on_tumour(std::int64_t k, std::int64_t t_us) {
  return pose_msg("scalpel", "Ref", Eigen::Isometry3d::Identity(), k, t_us);
}

struct Capture {  // the sealed bytes on the wire, as an attacker records them
  std::vector<std::vector<std::uint8_t>> bytes;
  void raw(const lcm::ReceiveBuffer* r, const std::string&) {
    const auto* p = static_cast<const std::uint8_t*>(r->data);
    bytes.emplace_back(p, p + r->data_size);
  }
};

void drain(seal::SealedLcm& bus) {
  while (bus.handleTimeout(0) > 0) {
  }
}

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

class SealedSession : public CoarseLiverSuite {};

TEST_F(SealedSession, DroppedMessagesReachOnlyTheBanner) {
  SessionFolder f("sealed_bus");
  const SessionConfig config = load_session(sealed_session(f));
  ASSERT_EQ(config.security.mode, seal::SecuritySettings::Mode::Sealed);
  SessionOptions o;
  o.threaded = false;
  o.keep_last_frame = true;
  NavigationSession session(config, std::make_unique<Scene>(*scene_), o);
  seal::BusSecurity security = seal::resolve_security(config.security);
  seal::SealedLcm bus("memq://", security);
  ASSERT_TRUE(bus.good());
  SessionHandler handler{{session, false}};
  connect_session(bus, handler, "");  // frames are rendered here, on this thread
  Capture capture;
  bus.raw().subscribe(std::string(channels::pose("liver_marker")), &Capture::raw, &capture);

  std::int64_t k = 0;
  // One frame: its board pose over the bus, then the frame rendered `later_us` after now.
  const auto frame = [&](std::int64_t later_us) {
    const tool_pose_t board = pose_msg("liver_marker", "Cam", test_X_CamRef(k), k, monotonic_us());
    bus.publish(channels::pose("liver_marker"), &board);
    drain(bus);
    const std::int64_t now_us = monotonic_us() + later_us;
    session.advance_model(now_us);
    return session.render_frame(frame_msg(k++, monotonic_us(), 640, 360), now_us);
  };
  // Genuine traffic: the overlay, no security banner.
  for (int i = 0; i < 3; ++i) {
    const FrameResult r = frame(0);
    EXPECT_TRUE(r.row.tumour_px) << r.row.flags;
    EXPECT_FALSE(contains(r.row.flags, "security")) << r.row.flags;
    for (const auto& b : r.banners) EXPECT_FALSE(contains(b, "SECURITY")) << b;
  }
  ASSERT_GE(capture.bytes.size(), 3u);
  const std::uint64_t board_messages = session.tracker_at(monotonic_us()).tools().at("liver_marker").messages;

  // The attacks, through the plain bus underneath (what someone on the network without the key can do).
  lcm::LCM& raw = bus.raw();
  const auto send = [&](const std::string& channel, const std::vector<std::uint8_t>& b) {
    raw.publish(channel, b.data(), static_cast<unsigned>(b.size()));
  };
  const std::string scalpel_ch = channels::pose("scalpel"), input_ch(channels::kInput);
  send(scalpel_ch, encoded(scalpel_on_tumour(1, monotonic_us())));  // unsealed pose
  send(input_ch, encoded(input_msg("pedal_cut", true, 1, monotonic_us())));  // unsealed pedal press
  {
    seal::Sealer other(random_key());  // sealed with a key the host does not hold
    std::vector<std::uint8_t> env;
    other.seal(scalpel_ch, encoded(scalpel_on_tumour(2, monotonic_us())), wall_now_us(), env);
    send(scalpel_ch, env);
    other.seal(input_ch, encoded(input_msg("pedal_cut", true, 2, monotonic_us())), wall_now_us(), env);
    send(input_ch, env);
  }
  send(channels::pose("liver_marker"), capture.bytes[0]);  // replayed
  std::vector<std::uint8_t> flipped = capture.bytes[1];
  flipped[flipped.size() - 3] ^= 0x04;
  send(channels::pose("liver_marker"), flipped);             // tampered
  send(scalpel_ch, capture.bytes[2]);                        // a genuine message moved to another channel: tampered
  drain(bus);
  const seal::OpenCounters c = bus.counters().open;
  EXPECT_EQ(c.unsealed, 2u);
  EXPECT_EQ(c.forged, 2u);
  EXPECT_EQ(c.replayed, 1u);
  EXPECT_EQ(c.tampered, 2u);

  // The next frames: the banner on top, flagged; nothing of the attack in the session.
  const FrameResult r = frame(0);
  ASSERT_GE(r.banners.size(), 2u) << r.row.flags;
  EXPECT_EQ(r.banners[0], "SECURITY: bus messages rejected (last 5 s): forged 2, tampered 2, replayed 1");
  EXPECT_EQ(r.banners[1], "SECURITY: unsealed messages on the sealed bus (last 5 s): 2, last on ARNAV_INPUT");
  EXPECT_TRUE(contains(r.row.flags, "security_rejected")) << r.row.flags;
  EXPECT_TRUE(contains(r.row.flags, "security_unsealed")) << r.row.flags;
  EXPECT_TRUE(contains(r.row.flags, "scalpel_stale")) << "no scalpel pose was accepted: " << r.row.flags;
  EXPECT_TRUE(r.row.tumour_px) << "the genuine overlay goes on";
  EXPECT_FALSE(r.row.blade_to_margin_mm);
  EXPECT_TRUE(session.cut_strokes().empty());
  const ToolFreshnessTracker tracker = session.tracker_at(monotonic_us());
  EXPECT_FALSE(tracker.tools().count("scalpel"));
  EXPECT_EQ(tracker.tools().at("liver_marker").messages, board_messages + 1) << "the next frame's board pose only";
  const nlohmann::json j = session.summary_json(1.0);
  EXPECT_FALSE(j.contains("inputs")) << j["inputs"].dump();  // no pedal message reached the session
  // Said once, at the first drop.
  const auto security_said = [&] {
    std::vector<std::string> out;
    for (const auto& m : session.messages())
      if (m.rfind("security:", 0) == 0) out.push_back(m);
    return out;
  };
  std::vector<std::string> said = security_said();
  ASSERT_EQ(said.size(), 1u);
  EXPECT_EQ(said[0], "security: ALERT: unsealed message on ARNAV_POSE_scalpel rejected (not used); the overlay shows a SECURITY banner while "
                     "messages are rejected");

  // Quiet for the hold time: the banner goes, the end is said.
  const FrameResult later = frame(5 * kS + 1);
  for (const auto& b : later.banners) EXPECT_FALSE(contains(b, "SECURITY")) << b;
  EXPECT_FALSE(contains(later.row.flags, "security")) << later.row.flags;
  said = security_said();
  ASSERT_EQ(said.size(), 2u);
  EXPECT_EQ(said[1], "security: alert over, no message rejected for 5 s; rejected so far 7 (forged 2, tampered 2, replayed 1, stale 0, unsealed 2, "
                     "malformed 0)");
  const nlohmann::json end = session.summary_json(1.0);
  EXPECT_EQ(end["security_banner"]["alerts"], 1);
  EXPECT_EQ(end["security_banner"]["dropped"], 7);
  EXPECT_EQ(end["flags"]["security_rejected"]["episodes"], 1);
  EXPECT_EQ(end["flags"]["security_unsealed"]["frames"], 1);
  EXPECT_TRUE(contains(session.format_summary(1.0), "security: 1 alert(s)"));
}

TEST_F(SealedSession, EachAlertStartsAndEndsOnceWithoutFrames) {
  SessionFolder f("sealed_alerts");
  SessionOptions o;
  o.threaded = false;
  NavigationSession session(load_session(sealed_session(f)), std::make_unique<Scene>(*scene_), o);
  const std::int64_t t0 = 100 * kS;
  session.on_bus_drop(seal::Verdict::Forged, "ARNAV_INPUT", t0);
  session.on_bus_drop(seal::Verdict::Replayed, "ARNAV_INPUT", t0 + kS);
  // 10 s later, no frame in between: the first alert ends before the second starts.
  session.on_bus_drop(seal::Verdict::Unsealed, "ARNAV_POSE_scalpel", t0 + 11 * kS);
  std::vector<std::string> said;
  for (const auto& m : session.messages())
    if (m.rfind("security:", 0) == 0) said.push_back(m);
  ASSERT_EQ(said.size(), 3u);
  EXPECT_TRUE(contains(said[0], "security: ALERT: forged message on ARNAV_INPUT"));
  EXPECT_TRUE(contains(said[1], "security: alert over, no message rejected for 5 s; rejected so far 2 (forged 1, tampered 0, replayed 1")) << said[1];
  EXPECT_TRUE(contains(said[2], "security: ALERT: unsealed message on ARNAV_POSE_scalpel"));
  session.status_table(t0 + 17 * kS);  // the status table notices the end too
  EXPECT_TRUE(contains(session.messages().back(), "security: alert over")) << session.messages().back();
  EXPECT_EQ(session.summary_json(1.0)["security_banner"]["alerts"], 2);
}

// arnav-host --replay on a sealed lcm-logger log with an attack in it.
std::string arnav_host() {
  const char* d = std::getenv("ARNAV_BINARY_DIR");
  return std::string(d ? d : ".") + "/host/app/arnav-host";
}

int run(const std::string& cmd, std::string* output) {
  FILE* p = ::popen((cmd + " 2>&1").c_str(), "r");
  if (!p) return -1;
  char buf[4096];
  output->clear();
  while (std::fgets(buf, sizeof buf, p)) *output += buf;
  const int status = ::pclose(p);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::vector<std::vector<std::string>> read_csv(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::vector<std::vector<std::string>> rows;
  std::getline(in, line);
  while (std::getline(in, line)) {
    std::vector<std::string> row;
    std::stringstream ss(line);
    std::string x;
    while (std::getline(ss, x, ',')) row.push_back(x);
    rows.push_back(row);
  }
  return rows;
}

TEST(SealedReplay, TheBannerOnTheFramesAfterTheLoggedAttack) {
  SessionFolder f("sealed_replay");
  const std::string session = sealed_session(f);
  const seal::BusSecurity security = seal::resolve_security(load_session(session).security);
  const std::string log_path = (f.dir / "session.lcmlog").string();
  constexpr std::int64_t kWall = 1'700'000'000'000'000;  // pose_msg's wall = mono + kWall
  // 10 Hz frames for 8 s (640x360); at 1 s an unsealed scalpel pose and a replayed board pose.
  {
    lcm::LogFile log(log_path, "w");
    ASSERT_TRUE(log.good());
    seal::Sealer appliance(security.key);
    std::vector<std::uint8_t> env, first_board;
    const auto write = [&](const std::string& channel, const std::vector<std::uint8_t>& bytes, std::int64_t wall_us) {
      lcm::LogEvent ev{};
      ev.timestamp = wall_us;
      ev.channel = channel;
      ev.datalen = static_cast<std::int32_t>(bytes.size());
      ev.data = const_cast<std::uint8_t*>(bytes.data());
      log.writeEvent(&ev);
    };
    const std::int64_t t0 = 10 * kS;
    for (std::int64_t k = 0; k < 80; ++k) {
      const std::int64_t t = t0 + k * 100'000;
      const std::string board_ch = channels::pose("liver_marker");
      appliance.seal(board_ch, encoded(pose_msg("liver_marker", "Cam", test_X_CamRef(k), k, t)), t + kWall + 500, env);
      if (k == 0) first_board = env;
      write(board_ch, env, t + kWall + 700);
      if (k == 10) {
        write(channels::pose("scalpel"), encoded(scalpel_on_tumour(k, t)), t + kWall + 800);
        write(board_ch, first_board, t + kWall + 900);
      }
      image_frame_t frame = frame_msg(k, t, 640, 360);
      appliance.seal(channels::frame("cam0"), encoded(frame), t + kWall + 3500, env);
      write(channels::frame("cam0"), env, t + kWall + 4000);
    }
  }
  std::string out;
  ASSERT_EQ(run(arnav_host() + " " + session + " --replay " + log_path + " --replay-speed 0 --quiet --record " + (f.dir / "rec").string() +
                    " --summary-json " + (f.dir / "replay.json").string(),
                &out),
            0)
      << out;
  EXPECT_TRUE(contains(out, "security: ALERT: unsealed message on ARNAV_POSE_scalpel rejected")) << out;
  EXPECT_TRUE(contains(out, "security: alert over, no message rejected for 5 s; rejected so far 2 (forged 0, tampered 0, replayed 1, stale 0, unsealed 1")) << out;
  const auto rows = read_csv((f.dir / "rec" / "overlay.csv").string());
  ASSERT_EQ(rows.size(), 80u);
  for (const auto& row : rows) {
    ASSERT_GE(row.size(), 10u);
    const std::int64_t k = std::stoll(row[0]);
    const std::string& flags = row[9];
    // The attack's messages are logged before frame 10's: frames 10..59 are within 5 s of it.
    const bool expected = k >= 10 && k < 60;
    EXPECT_EQ(contains(flags, "security_rejected"), expected) << "frame " << k << ": " << flags;
    EXPECT_EQ(contains(flags, "security_unsealed"), expected) << "frame " << k << ": " << flags;
    EXPECT_TRUE(contains(flags, "scalpel_stale")) << "frame " << k << ": " << flags;
    EXPECT_TRUE(row[8].empty()) << "no blade-to-margin distance: frame " << k;
    EXPECT_FALSE(row[6].empty()) << "the overlay: frame " << k << ": " << flags;
  }
  std::ifstream in(f.dir / "replay.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j["security"]["unsealed"], 1);
  EXPECT_EQ(j["security"]["replayed"], 1);
  EXPECT_EQ(j["navigation"]["security_banner"]["alerts"], 1);
  EXPECT_EQ(j["navigation"]["flags"]["security_rejected"]["frames"], 50);
}

}  // namespace
}  // namespace arnav::host
