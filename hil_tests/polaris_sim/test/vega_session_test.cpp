// The NDI driver's session (appliance/ndi) over TCP against the simulated Vega, in one
// process: the server runs on its own thread on 127.0.0.1. Streamed BX2, polled BX2 and
// BX by API revision, device timestamps, frame-number gaps, corrupt CRCs, split writes,
// stalls, a connection reset and a clean USTREAM/TSTOP.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <thread>

#include "appliance/ndi/session.hpp"
#include "appliance/ndi/tcp_transport.hpp"
#include "hil_tests/polaris_sim/vega_server.hpp"
#include "protocol/clock.hpp"

namespace arnav::hil {
namespace {

std::string rom(const std::string& name) { return std::string(std::getenv("ARNAV_DATA_DIR")) + "/ndi_roms/" + name; }

class VegaBench {
 public:
  VegaBench(VegaOptions options, std::vector<std::string> faults, double rate_hz = 400.0) {
    Scenario s;
    s.frame_rate_hz = rate_hz;
    add_tool_spec(s, "pointer=" + rom("8700340.rom"));
    add_tool_spec(s, "reference=" + rom("8700339.rom"));
    std::vector<VegaFault> parsed;
    for (const auto& f : faults) parsed.push_back(parse_vega_fault(f));
    model_ = std::make_unique<PolarisModel>(std::move(s));
    server_ = std::make_unique<VegaServer>(*model_, std::move(options), std::move(parsed));
    port_ = server_->start();
    thread_ = std::thread([this] { server_->run(stop_); });
  }
  ~VegaBench() { stop(); }
  void stop() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }
  const VegaServer::Stats& stats() const { return server_->stats(); }  // after stop()

  std::unique_ptr<ndi::Session> session(bool stream = true) {
    ndi::SessionConfig c;
    c.tools = {{"pointer", rom("8700340.rom")}, {"reference", rom("8700339.rom")}};
    c.stream = stream;
    c.setup_timeout = std::chrono::milliseconds(5000);
    // Generous: on a loaded machine the server thread may be starved for a while; a
    // timeout here would test the machine, not the session.
    c.tracking_timeout = std::chrono::milliseconds(2000);
    ndi::TcpOptions o;
    o.host = "127.0.0.1";
    o.port = port_;
    return std::make_unique<ndi::Session>(
        c, [o] { return std::unique_ptr<ndi::Transport>(new ndi::TcpTransport(o)); },
        [this](const ndi::Event& e) { events_.push_back(std::string(e.code) + ": " + e.text); });
  }
  std::string events() const {
    std::string s;
    for (const auto& e : events_) s += e + "\n";
    return s;
  }

 private:
  std::unique_ptr<PolarisModel> model_;
  std::unique_ptr<VegaServer> server_;
  int port_ = 0;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  std::vector<std::string> events_;
};

struct Tally {
  int new_frames = 0, same = 0, failed = 0;
  std::int64_t worst_age_us = 0;  // receive time - device time, worst
};

// Polls until `frames` new frames came (or 30 s passed: a broken link); every new frame's
// poses must be sane. Counts, not host time: the faults are timed on the device clock.
Tally track(ndi::Session& s, int frames) {
  Tally t;
  ndi::TrackingReply r;
  const std::int64_t end = monotonic_us() + 30'000'000;
  while (t.new_frames < frames && monotonic_us() < end) {
    if (s.state() != ndi::LinkState::Tracking) {
      s.start();
      continue;
    }
    std::int64_t rx = 0;
    switch (s.poll(r, rx)) {
      case ndi::PollResult::NewFrame:
        ++t.new_frames;
        for (std::size_t i = 0; i < r.count; ++i) {
          const auto& h = r.handles[i];
          if (h.state != ndi::HandleState::Valid) continue;
          const auto& q = h.q_NdiTool_wxyz;
          const double qn = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
          EXPECT_NEAR(qn, 1.0, 1e-5);
          EXPECT_TRUE(std::isfinite(h.p_NdiTool_mm[0]) && std::isfinite(h.p_NdiTool_mm[1]) && std::isfinite(h.p_NdiTool_mm[2]));
        }
        if (r.has_device_time) t.worst_age_us = std::max(t.worst_age_us, rx - r.device_time_ns / 1000);
        break;
      case ndi::PollResult::SameFrame: ++t.same; break;
      case ndi::PollResult::Failed: ++t.failed; break;
    }
  }
  return t;
}

TEST(VegaSession, StreamsBx2WithDeviceTimestampsAndStopsCleanly) {
  VegaBench bench({}, {});
  auto s = bench.session();
  ASSERT_TRUE(s->start()) << s->detail() << "\n" << bench.events();
  EXPECT_EQ(s->reply_mode(), ndi::ReplyMode::StreamedBx2);
  EXPECT_TRUE(s->streaming());
  EXPECT_EQ(s->api_major(), 3);
  const Tally t = track(*s, 200);
  EXPECT_EQ(t.new_frames, 200);
  EXPECT_EQ(t.failed, 0) << bench.events();
  EXPECT_EQ(s->counters().dropped_frames, 0);
  EXPECT_EQ(s->counters().crc_errors, 0);
  // Device time is the frame's instant on this machine's monotonic clock: a frame is
  // received after it happened. (No upper bound: that would be a timing test.)
  EXPECT_GE(t.worst_age_us, 0);
  s->stop();
  EXPECT_EQ(s->state(), ndi::LinkState::Down);
  // Packets that raced USTREAM's OKAY were set aside, not taken as its reply.
  EXPECT_GE(s->counters().stray_stream_packets, 2);
  EXPECT_NE(bench.events().find("NDI_TRACKING_STOPPED"), std::string::npos) << bench.events();
}

TEST(VegaSession, MissingFrameNumbersAreLostFramesAndDuplicatesAreNotNewFrames) {
  VegaBench bench({}, {"0.1:skip 3", "0.2:duplicate 2", "0.3:skip 1"});
  auto s = bench.session();
  ASSERT_TRUE(s->start()) << s->detail();
  const Tally t = track(*s, 400);  // 1 s of device time: every fault has happened
  EXPECT_EQ(s->counters().dropped_frames, 4);
  EXPECT_EQ(t.same, 2);
  EXPECT_EQ(t.failed, 0);
  s->stop();
}

TEST(VegaSession, CorruptFramesNeverGiveAPoseAndCountAsLost) {
  VegaBench bench({}, {"0.1:bad_crc 3"});
  auto s = bench.session();
  ASSERT_TRUE(s->start()) << s->detail();
  const Tally t = track(*s, 200);
  EXPECT_EQ(s->counters().crc_errors, 3);
  EXPECT_EQ(t.failed, 3);
  EXPECT_EQ(s->counters().dropped_frames, 3);  // their frame numbers never arrive intact
  EXPECT_EQ(s->state(), ndi::LinkState::Tracking);
  s->stop();
}

TEST(VegaSession, SplitWritesAndAStallLoseNothing) {
  // The device's clock runs on during a stall; the frames due then arrive late, together.
  VegaBench bench({}, {"0.1:split 100", "0.3:stall 0.08"});
  auto s = bench.session();
  ASSERT_TRUE(s->start()) << s->detail();
  const Tally t = track(*s, 400);
  EXPECT_EQ(s->counters().dropped_frames, 0);
  EXPECT_EQ(t.failed, 0) << bench.events();
  EXPECT_EQ(t.new_frames, 400);
  s->stop();
}

TEST(VegaSession, ConnectionResetIsRecoveredAndStreamingResumes) {
  VegaBench bench({}, {"0.2:reset"});
  auto s = bench.session();
  ASSERT_TRUE(s->start()) << s->detail();
  ndi::TrackingReply r;
  std::int64_t rx = 0;
  bool lost = false;
  const std::int64_t end = monotonic_us() + 3'000'000;
  while (monotonic_us() < end && !lost) {
    s->poll(r, rx);
    lost = s->state() == ndi::LinkState::Recovering;
  }
  ASSERT_TRUE(lost) << bench.events();
  const std::int64_t t0 = monotonic_us();
  bool back = false;
  while (!back && monotonic_us() - t0 < 5'000'000) back = s->start();
  ASSERT_TRUE(back) << s->detail() << "\n" << bench.events();
  EXPECT_TRUE(s->streaming());
  EXPECT_EQ(s->counters().reconnects, 1);
  const std::int64_t dropped_before = s->counters().dropped_frames;
  const Tally t = track(*s, 50);
  EXPECT_EQ(t.new_frames, 50);
  EXPECT_EQ(t.failed, 0);
  // The unit tracked on while the link was down: those frames are counted as lost.
  EXPECT_GT(s->counters().dropped_frames, dropped_before);
  s->stop();
  bench.stop();
  EXPECT_EQ(bench.stats().connections, 2u);
  EXPECT_EQ(bench.stats().resets, 1u);
}

TEST(VegaSession, StreamRefusedFallsBackToPolledBx2) {
  VegaOptions o;
  o.stream_supported = false;
  VegaBench bench(o, {}, 100.0);
  auto s = bench.session();
  ASSERT_TRUE(s->start()) << s->detail();
  EXPECT_EQ(s->reply_mode(), ndi::ReplyMode::Bx2);
  EXPECT_NE(bench.events().find("NDI_STREAM_REFUSED"), std::string::npos);
  const Tally t = track(*s, 20);
  EXPECT_EQ(t.new_frames, 20);
  EXPECT_EQ(t.failed, 0);
  s->stop();
}

TEST(VegaSession, StreamingCanBeTurnedOffAndOldApiRevisionsArePolledWithBx) {
  {
    VegaBench bench({}, {}, 100.0);
    auto s = bench.session(false);
    ASSERT_TRUE(s->start()) << s->detail();
    EXPECT_EQ(s->reply_mode(), ndi::ReplyMode::Bx2);
    s->stop();
  }
  VegaOptions o;
  o.api_revision = "G.001.004";
  VegaBench bench(o, {}, 100.0);
  auto s = bench.session();
  ASSERT_TRUE(s->start()) << s->detail();
  EXPECT_EQ(s->reply_mode(), ndi::ReplyMode::Bx);
  EXPECT_EQ(s->api_major(), 1);
  const Tally t = track(*s, 20);
  EXPECT_EQ(t.new_frames, 20);
  s->stop();
}

TEST(VegaFaults, SpecsParseAndBadOnesAreRefusedWithTheSpec) {
  const VegaFault f = parse_vega_fault("2.5:stall 0.1");
  EXPECT_EQ(f.kind, VegaFault::Kind::kStall);
  EXPECT_DOUBLE_EQ(f.at_s, 2.5);
  EXPECT_DOUBLE_EQ(f.seconds, 0.1);
  EXPECT_EQ(parse_vega_fault("1:skip 4").count, 4);
  for (const char* bad : {"reset", "x:reset", "1:explode", "1:stall abc", "1:reset 3", "-1:reset"}) {
    try {
      parse_vega_fault(bad);
      ADD_FAILURE() << bad;
    } catch (const ScenarioError& e) {
      EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace arnav::hil
