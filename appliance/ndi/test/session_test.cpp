#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>

#include <unistd.h>

#include <sstream>

#include "appliance/ndi/recording_transport.hpp"
#include "appliance/ndi/session.hpp"
#include "appliance/ndi/test/fake_polaris.hpp"

namespace arnav::ndi {
namespace {

using namespace std::chrono_literals;
using test::FakeDevice;

std::filesystem::path rom(const std::string& name) {
  const char* data = std::getenv("ARNAV_DATA_DIR");
  if (!data) throw std::runtime_error("ARNAV_DATA_DIR is not set (run the test through ctest)");
  return std::filesystem::path(data) / "ndi_roms" / name;
}

SessionConfig fast_config(int tools = 2) {
  SessionConfig c;
  const char* roms[] = {"8700340.rom", "8700339.rom", "8700449.rom"};
  const char* names[] = {"pointer", "reference", "probe"};
  for (int i = 0; i < tools; ++i) c.tools.push_back({names[i], rom(roms[i])});
  c.target_baud = 115200;
  c.setup_timeout = 300ms;
  c.probe_timeout = 40ms;
  c.tracking_timeout = 30ms;
  c.reset_wait = 80ms;
  c.break_duration = 1ms;
  c.comm_settle = 1ms;
  return c;
}

struct Harness {
  std::shared_ptr<FakeDevice> dev = std::make_shared<FakeDevice>();
  std::vector<Event> events;
  std::unique_ptr<Session> session;

  explicit Harness(SessionConfig c = fast_config()) { make(std::move(c)); }
  void make(SessionConfig c) {
    session = std::make_unique<Session>(std::move(c), test::fake_factory(dev), [this](const Event& e) { events.push_back(e); });
  }
  int count(std::string_view code) const {
    return static_cast<int>(std::count_if(events.begin(), events.end(), [&](const Event& e) { return e.code == code; }));
  }
  PollResult poll(TrackingReply& t) {
    std::int64_t rx = 0;
    return session->poll(t, rx);
  }
};

TEST(Session, BringUpLoadsRomsAndTracks) {
  Harness h;
  ASSERT_TRUE(h.session->start()) << h.session->detail();
  EXPECT_EQ(h.session->state(), LinkState::Tracking);
  EXPECT_EQ(h.session->baud(), 115200);
  EXPECT_EQ(h.dev->device_baud, 115200);
  EXPECT_EQ(h.session->firmware(), "Polaris Vicra Control Firmware");
  EXPECT_EQ(h.session->serial_number(), "P6-01234");
  EXPECT_EQ(h.dev->breaks, 1);

  // Command order (PVWR collapsed).
  std::vector<std::string> seq;
  for (const auto& c : h.dev->commands)
    if (seq.empty() || c != "PVWR" || seq.back() != "PVWR") seq.push_back(c);
  const std::vector<std::string> expected = {"INIT", "COMM", "VER", "PHSR", "PHRQ", "PVWR", "PHRQ", "PVWR",
                                             "PINIT", "PINIT", "PHINF", "PENA", "PHINF", "PENA", "TSTART"};
  EXPECT_EQ(seq, expected);
  EXPECT_EQ(std::count(h.dev->commands.begin(), h.dev->commands.end(), "PVWR"), 32);

  // The ROM bytes arrived intact, zero padded to 1024.
  for (const auto& tool : h.session->tools()) {
    const auto& written = h.dev->roms.at(tool.handle);
    ASSERT_EQ(written.size(), 1024u);
    EXPECT_TRUE(std::equal(tool.rom.bytes.begin(), tool.rom.bytes.end(), written.begin()));
    EXPECT_TRUE(std::all_of(written.begin() + 752, written.end(), [](std::uint8_t b) { return b == 0; }));
    EXPECT_EQ(tool.info.manufacturer, "NDI");
  }

  TrackingReply t;
  ASSERT_EQ(h.poll(t), PollResult::NewFrame);
  ASSERT_EQ(t.count, 2u);
  EXPECT_GE(h.session->tool_index(t.handles[0].handle), 0);
  EXPECT_EQ(t.handles[0].state, HandleState::Valid);
  ASSERT_EQ(h.poll(t), PollResult::NewFrame);
  EXPECT_EQ(h.session->counters().frames_total, 2);
  EXPECT_EQ(h.session->counters().dropped_frames, 0);

  h.session->stop();
  EXPECT_EQ(h.dev->commands.back(), "COMM");
  EXPECT_EQ(h.dev->comm_params.back(), "00000");
  EXPECT_FALSE(h.dev->tracking);
  EXPECT_EQ(h.dev->device_baud, 9600);
  EXPECT_EQ(h.dev->host_baud, 9600);
  EXPECT_EQ(h.session->state(), LinkState::Down);
}

TEST(Session, CommFallsBackToLowerRates) {
  Harness h;
  h.dev->refuse_rates = {115200};
  h.dev->broken_rates = {57600};
  ASSERT_TRUE(h.session->start()) << h.session->detail();
  EXPECT_EQ(h.session->baud(), 38400);
  EXPECT_EQ(h.dev->device_baud, 38400);
  EXPECT_EQ(h.count("NDI_BAUD_FALLBACK"), 2);
  TrackingReply t;
  EXPECT_EQ(h.poll(t), PollResult::NewFrame);
}

TEST(Session, NoResetOnAPtyProbesBaudRatesAndStopsStaleTracking) {
  Harness h;
  h.dev->break_resets = false;  // a pty swallows the break
  // A crashed host left the unit tracking at 115200.
  h.dev->device_baud = h.dev->host_baud = 115200;
  h.dev->initialised = h.dev->tracking = true;
  ASSERT_TRUE(h.session->start()) << h.session->detail();
  EXPECT_EQ(h.count("NDI_NO_RESET_REPLY"), 1);
  EXPECT_EQ(h.session->baud(), 115200);
  TrackingReply t;
  EXPECT_EQ(h.poll(t), PollResult::NewFrame);
}

TEST(Session, StaleTrackingUnitThatAcceptsInitIsStoppedFirst) {
  Harness h;
  h.dev->break_resets = false;
  h.dev->init_ok_while_tracking = true;
  h.dev->device_baud = h.dev->host_baud = 57600;
  h.dev->initialised = h.dev->tracking = true;
  ASSERT_TRUE(h.session->start()) << h.session->detail();
  EXPECT_EQ(h.session->counters().error_replies, 0);
  TrackingReply t;
  EXPECT_EQ(h.poll(t), PollResult::NewFrame);
  EXPECT_EQ(t.count, 2u);
}

TEST(Session, NonNdiRomIsRefusedBeforeAnyTraffic) {
  auto bad = std::filesystem::temp_directory_path() / ("arnav_session_bad_" + std::to_string(::getpid()) + ".rom");
  std::ofstream(bad) << "<tool>not a rom</tool>\n";
  SessionConfig c = fast_config(1);
  c.tools.push_back({"bad", bad});
  auto dev = std::make_shared<FakeDevice>();
  try {
    Session s(c, test::fake_factory(dev), nullptr);
    ADD_FAILURE() << "accepted a non-NDI ROM";
  } catch (const RomError& e) {
    EXPECT_NE(std::string(e.what()).find(bad.string()), std::string::npos) << e.what();
  }
  EXPECT_EQ(dev->opens, 0);
  EXPECT_EQ(dev->bytes_from_host, 0u);
  std::filesystem::remove(bad);
}

TEST(Session, CorruptBxNeverGivesAPoseAndFallsBackToTx) {
  SessionConfig c = fast_config();
  c.bx_failures_before_tx = 4;
  Harness h(c);
  ASSERT_TRUE(h.session->start());
  h.dev->bx_always_corrupt = true;
  TrackingReply t;
  for (int i = 0; i < 4; ++i) {
    EXPECT_EQ(h.poll(t), PollResult::Failed);
    EXPECT_EQ(t.count, 0u);
  }
  EXPECT_EQ(h.count("NDI_CRC_ERROR"), 4);
  EXPECT_EQ(h.count("NDI_TX_FALLBACK"), 1);
  EXPECT_FALSE(h.session->using_bx());
  ASSERT_EQ(h.poll(t), PollResult::NewFrame);
  EXPECT_EQ(h.dev->commands.back(), "TX");
  EXPECT_EQ(t.count, 2u);
  EXPECT_EQ(h.session->counters().crc_errors, 4);

  // After a recovery the session stays on TX.
  h.dev->spontaneous_reset();
  for (int i = 0; i < 3; ++i) h.poll(t);
  ASSERT_EQ(h.session->state(), LinkState::Recovering);
  ASSERT_TRUE(h.session->start());
  EXPECT_FALSE(h.session->using_bx());
  ASSERT_EQ(h.poll(t), PollResult::NewFrame);
  EXPECT_EQ(h.dev->commands.back(), "TX");
}

TEST(Session, OccasionalCorruptionStaysOnBx) {
  Harness h;
  ASSERT_TRUE(h.session->start());
  h.dev->bx_corrupt_every = 3;
  TrackingReply t;
  int good = 0, bad = 0;
  for (int i = 0; i < 30; ++i) (h.poll(t) == PollResult::NewFrame ? good : bad)++;
  EXPECT_EQ(good, 20);
  EXPECT_EQ(bad, 10);
  EXPECT_TRUE(h.session->using_bx());
  EXPECT_EQ(h.session->counters().crc_errors, 10);
  EXPECT_EQ(h.session->state(), LinkState::Tracking);
}

TEST(Session, GarbageAndChunkedRepliesAreResynchronised) {
  Harness h;
  ASSERT_TRUE(h.session->start());
  h.dev->garbage_before_bx = std::string("\x00\xFFjunk\xC4", 7);
  h.dev->chunk = 5;
  TrackingReply t;
  for (int i = 0; i < 10; ++i) ASSERT_EQ(h.poll(t), PollResult::NewFrame);
  EXPECT_EQ(h.session->counters().garbage_bytes, 70);
  EXPECT_GE(h.session->counters().resyncs, 10);
}

TEST(Session, RecoversFromASpontaneousDeviceReset) {
  Harness h;
  ASSERT_TRUE(h.session->start());
  TrackingReply t;
  ASSERT_EQ(h.poll(t), PollResult::NewFrame);
  h.dev->spontaneous_reset();  // back to 9600: its RESET is lost at our 115200
  for (int i = 0; i < 3; ++i) EXPECT_EQ(h.poll(t), PollResult::Failed);
  EXPECT_EQ(h.session->state(), LinkState::Recovering);
  EXPECT_EQ(h.count("NDI_RECOVERING"), 1);
  ASSERT_TRUE(h.session->start()) << h.session->detail();
  EXPECT_EQ(h.count("NDI_RECOVERED"), 1);
  ASSERT_EQ(h.poll(t), PollResult::NewFrame);
  EXPECT_EQ(t.count, 2u);
  EXPECT_EQ(h.session->counters().timeouts, 4);  // three polls and the last-chance poll before recovery
}

TEST(Session, ResetMessageWhileTrackingIsReported) {
  SessionConfig c = fast_config(1);
  c.target_baud = 9600;  // the RESET is readable at 9600
  Harness h(c);
  ASSERT_TRUE(h.session->start());
  h.dev->spontaneous_reset();
  TrackingReply t;
  EXPECT_EQ(h.poll(t), PollResult::Failed);
  EXPECT_EQ(h.count("NDI_DEVICE_RESET"), 1);
  EXPECT_EQ(h.session->state(), LinkState::Recovering);
  ASSERT_TRUE(h.session->start());
  EXPECT_EQ(h.poll(t), PollResult::NewFrame);
}

TEST(Session, VanishedPortIsReopened) {
  Harness h;
  ASSERT_TRUE(h.session->start());
  h.dev->unplugged = true;
  TrackingReply t;
  EXPECT_EQ(h.poll(t), PollResult::Failed);
  EXPECT_EQ(h.count("NDI_PORT_LOST"), 1);
  EXPECT_EQ(h.session->state(), LinkState::Recovering);
  EXPECT_FALSE(h.session->start());
  EXPECT_EQ(h.count("NDI_PORT_OPEN_FAILED"), 1);
  h.dev->unplugged = false;
  h.dev->reset_device();  // power cycled with the cable
  ASSERT_TRUE(h.session->start()) << h.session->detail();
  EXPECT_EQ(h.session->counters().reconnects, 1);
  EXPECT_EQ(h.count("NDI_RECOVERED"), 1);
  EXPECT_EQ(h.poll(t), PollResult::NewFrame);
}

TEST(Session, IsolatedTimeoutsAndErrorsAreCountedWithoutRecovery) {
  Harness h;
  ASSERT_TRUE(h.session->start());
  TrackingReply t;
  h.dev->drop_replies = 2;
  EXPECT_EQ(h.poll(t), PollResult::Failed);
  EXPECT_EQ(h.poll(t), PollResult::Failed);
  EXPECT_EQ(h.poll(t), PollResult::NewFrame);
  EXPECT_EQ(h.session->counters().timeouts, 2);
  h.dev->tracking = false;  // BX now answers ERROR0C
  EXPECT_EQ(h.poll(t), PollResult::Failed);
  EXPECT_EQ(h.session->counters().error_replies, 1);
  EXPECT_EQ(h.count("NDI_ERROR_REPLY"), 1);
  EXPECT_NE(h.events.back().text.find("INVALID_IN_MODE"), std::string::npos);
  EXPECT_EQ(h.session->state(), LinkState::Tracking);
}

// A link that stalls (three replies in a row missing: a pty on a loaded machine) but answers
// the last-chance poll goes on tracking without the ~4 s re-initialisation; one that stays
// silent is recovered as before.
TEST(Session, StalledLinkThatAnswersAgainIsNotReinitialised) {
  Harness h;
  ASSERT_TRUE(h.session->start());
  TrackingReply t;
  h.dev->drop_replies = 3;
  EXPECT_EQ(h.poll(t), PollResult::Failed);
  EXPECT_EQ(h.poll(t), PollResult::Failed);
  EXPECT_EQ(h.poll(t), PollResult::NewFrame);  // the third timeout's last-chance poll is answered
  EXPECT_EQ(h.session->state(), LinkState::Tracking);
  EXPECT_EQ(h.count("NDI_RESYNCED"), 1);
  EXPECT_EQ(h.count("NDI_RECOVERING"), 0);
  EXPECT_EQ(h.session->counters().timeouts, 3);
  EXPECT_EQ(h.poll(t), PollResult::NewFrame);

  h.dev->drop_replies = 4;  // silent through the last chance too: recovery
  EXPECT_EQ(h.poll(t), PollResult::Failed);
  EXPECT_EQ(h.poll(t), PollResult::Failed);
  EXPECT_EQ(h.poll(t), PollResult::Failed);
  EXPECT_EQ(h.session->state(), LinkState::Recovering);
  EXPECT_EQ(h.count("NDI_RECOVERING"), 1);
  EXPECT_EQ(h.session->counters().timeouts, 7);
  ASSERT_TRUE(h.session->start());
  EXPECT_EQ(h.poll(t), PollResult::NewFrame);
}

TEST(Session, FrameCounterGapsAreDroppedFrames) {
  Harness h;
  ASSERT_TRUE(h.session->start());
  h.dev->frame_step = 3;
  TrackingReply t;
  for (int i = 0; i < 5; ++i) ASSERT_EQ(h.poll(t), PollResult::NewFrame);
  EXPECT_EQ(h.session->counters().dropped_frames, 8);  // 4 gaps of 2
  h.dev->frame_step = 0;
  EXPECT_EQ(h.poll(t), PollResult::SameFrame);
}

TEST(Session, NoDeviceFailsCleanly) {
  Harness h;
  h.dev->break_resets = false;
  h.dev->device_baud = -1;  // nothing ever answers
  int idle_calls = 0;
  h.session->set_idle_callback([&] { ++idle_calls; });
  EXPECT_FALSE(h.session->start());
  EXPECT_GE(idle_calls, 5);  // the owner could publish health during the ~0.4 s of probing
  EXPECT_EQ(h.count("NDI_BRINGUP_FAILED"), 1);
  EXPECT_NE(h.session->detail().find("any baud rate"), std::string::npos);
  EXPECT_EQ(h.session->state(), LinkState::Down);
}

TEST(Session, ConfiguredTxFirmwarePollsWithTx) {
  SessionConfig c = fast_config();
  c.tx_firmware = {"Vicra Rev 007"};
  Harness h(c);
  ASSERT_TRUE(h.session->start());
  EXPECT_FALSE(h.session->using_bx());
  TrackingReply t;
  ASSERT_EQ(h.poll(t), PollResult::NewFrame);
  EXPECT_EQ(h.dev->commands.back(), "TX");
}

TEST(Session, CancelFlagEndsBringUpAtOnceButStopStillTalks) {
  SessionConfig c = fast_config();
  c.reset_wait = 5000ms;  // would take seconds without the flag
  c.setup_timeout = 5000ms;
  Harness h(c);
  h.dev->break_resets = false;
  h.dev->device_baud = -1;  // nothing answers
  volatile std::sig_atomic_t flag = 1;
  h.session->set_cancel_flag(&flag);
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_FALSE(h.session->start());
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 2s);

  // Cancelled after tracking started: stop() still sends TSTOP and COMM.
  Harness g;
  ASSERT_TRUE(g.session->start());
  volatile std::sig_atomic_t stop_now = 1;
  g.session->set_cancel_flag(&stop_now);
  TrackingReply t;
  EXPECT_EQ(g.poll(t), PollResult::Failed);
  g.session->stop();
  EXPECT_FALSE(g.dev->tracking);
  EXPECT_EQ(g.dev->device_baud, 9600);
}

TEST(Session, RecordingTransportWritesAReadableTranscript) {
  auto dev = std::make_shared<FakeDevice>();
  std::stringstream transcript;
  auto inner = test::fake_factory(dev);
  TransportFactory recording = [&] { return std::unique_ptr<Transport>(new RecordingTransport(inner(), transcript)); };
  {
    Session s(fast_config(1), recording, nullptr);
    ASSERT_TRUE(s.start());
    TrackingReply t;
    std::int64_t rx = 0;
    for (int i = 0; i < 3; ++i) ASSERT_EQ(s.poll(t, rx), PollResult::NewFrame);
    s.stop();
  }
  const auto records = read_transcript(transcript, "recorded");
  using K = TranscriptRecord::Kind;
  ASSERT_GT(records.size(), 20u);
  EXPECT_EQ(records[0].kind, K::Baud);
  EXPECT_EQ(records[1].kind, K::Break);
  EXPECT_EQ(records[2].kind, K::Reply);
  EXPECT_EQ(records[2].bytes, "RESETBE6F\r");
  EXPECT_EQ(records[3].bytes, "INIT:E3A5\r");
  int bx_replies = 0, bauds = 0;
  for (const auto& r : records) {
    if (r.kind == K::Reply && !r.bytes.empty() && static_cast<std::uint8_t>(r.bytes[0]) == 0xC4) ++bx_replies;
    if (r.kind == K::Baud && r.value == 115200) ++bauds;
  }
  EXPECT_EQ(bx_replies, 3);
  EXPECT_EQ(bauds, 1);
  EXPECT_EQ(records.back().kind, K::Baud);  // back to 9600 at the end
  EXPECT_EQ(records.back().value, 9600);
}

}  // namespace
}  // namespace arnav::ndi
