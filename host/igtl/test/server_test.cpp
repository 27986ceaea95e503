// arnav-igtl's server and LCM bridge on real sockets (127.0.0.1, a free port): a client that
// greets with 3D Slicer's v2 STATUS keeps receiving, keep-alives, TDATA on request, only the
// latest message per stream, dead/slow/garbage clients dropped without disturbing others,
// PLUS names, tools not seen not sent, IMAGE decoded to RGB. Waits are bounded by generous
// timeouts; nothing asserts on speed.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <mutex>
#include <thread>

#include <opencv2/imgcodecs.hpp>

#include "host/igtl/bridge.hpp"
#include "host/igtl/test/test_client.hpp"
#include "protocol/clock.hpp"
#include "protocol/pose_convert.hpp"

namespace arnav::igtl {
namespace {

using test::TestClient;

struct Logged {
  std::mutex mutex;
  std::vector<std::string> lines;
  Server::Log log() {
    return [this](const std::string& s) {
      std::lock_guard lock(mutex);
      lines.push_back(s);
    };
  }
  std::string all() {
    std::lock_guard lock(mutex);
    std::string s;
    for (const auto& l : lines) s += l + "\n";
    return s;
  }
};

ServerOptions test_options() {
  ServerOptions o;
  o.port = 0;
  return o;
}

template <class Pred>
bool wait_until(Pred pred, double timeout_s = 10.0) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (!pred()) {
    if (std::chrono::steady_clock::now() > end) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

std::size_t count_type(const std::vector<Message>& ms, const std::string& type, const std::string& name = "") {
  std::size_t n = 0;
  for (const auto& m : ms) n += m.header.type == type && (name.empty() || m.header.device_name == name) ? 1 : 0;
  return n;
}

Packet transform_packet(const std::string& name, double x) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.translation().x() = x;
  return pack_transform(name, X, wall_us());
}

TEST(IgtlServer, SlicerV2StatusFirstThenKeepsReceiving) {
  Logged logged;
  Server server(test_options(), logged.log());
  TestClient client(server.port());
  ASSERT_TRUE(client.connected()) << client.why();
  ASSERT_TRUE(client.send(test::slicer_v2_status()));
  ASSERT_TRUE(wait_until([&] { return server.stats().messages_skipped == 1; })) << logged.all();
  for (int i = 0; i < 5; ++i) {
    const std::string name = std::string("T").append(std::to_string(i));
    server.publish(name, transform_packet(name, i));
  }
  const auto& got = client.receive_until(5, 10.0);
  EXPECT_EQ(count_type(got, "TRANSFORM"), 5u) << logged.all();
  EXPECT_FALSE(client.closed_by_server());
  EXPECT_EQ(server.stats().clients_dropped, 0u);
}

TEST(IgtlServer, KeepAliveStatusOkWhenIdle) {
  Logged logged;
  Server server(test_options(), logged.log());
  TestClient client(server.port());
  ASSERT_TRUE(client.connected()) << client.why();
  const auto& got = client.receive_until(2, 10.0);
  ASSERT_EQ(got.size(), 2u);
  for (const auto& m : got) {
    const auto u = test::unpack(m);
    EXPECT_EQ(m.header.type, "STATUS");
    EXPECT_TRUE(u.crc_ok);
    EXPECT_EQ(u.status_code, 1);  // STATUS_OK
    EXPECT_NEAR(static_cast<double>(u.wall_us), static_cast<double>(wall_us()), 60e6);  // UTC, not zero
  }
}

TEST(IgtlServer, TdataOnlyBetweenStartAndStop) {
  Logged logged;
  Server server(test_options(), logged.log());
  TestClient client(server.port());
  ASSERT_TRUE(client.connected()) << client.why();
  ASSERT_TRUE(wait_until([&] { return server.clients() == 1; }));
  const Packet tdata = pack_tdata("ARNav", {{"PointerToTracker", Eigen::Isometry3d::Identity()}}, wall_us());
  server.publish_tdata("ARNav", tdata);  // not asked for yet
  ASSERT_TRUE(client.send(test::start_tdata_request(16)));
  ASSERT_TRUE(wait_until([&] { return server.stats().requests_handled == 1; }));
  server.publish_tdata("ARNav", tdata);
  client.receive_until(1000, 0.5);
  auto got = client.take();
  while (count_type(got, "TDATA") == 0 && !client.closed_by_server()) {
    client.receive_until(1, 5.0);
    for (auto& m : client.take()) got.push_back(std::move(m));
  }
  EXPECT_EQ(count_type(got, "TDATA"), 1u);
  ASSERT_TRUE(client.send(test::request("STP_TDATA")));
  ASSERT_TRUE(wait_until([&] { return server.stats().requests_handled == 2; }));
  server.publish_tdata("ARNav", tdata);
  server.publish("T", transform_packet("T", 1.0));  // a marker after the TDATA that must not come
  const auto& after = client.receive_until(1000, 1.0);
  EXPECT_EQ(count_type(after, "TDATA"), 0u);
  EXPECT_EQ(count_type(after, "TRANSFORM"), 1u);
}

TEST(IgtlServer, SlowClientGetsOnlyTheLatestPerStream) {
  Logged logged;
  Server server(test_options(), logged.log());
  TestClient client(server.port());
  ASSERT_TRUE(client.connected()) << client.why();
  ASSERT_TRUE(wait_until([&] { return server.clients() == 1; }));
  constexpr int kPublished = 20000;
  for (int i = 0; i <= kPublished; ++i) server.publish("PointerToTracker", transform_packet("PointerToTracker", i));
  // Read until the last published pose arrives: it always does, nothing later is queued.
  double last_x = -1;
  std::size_t transforms = 0;
  while (last_x != kPublished && !client.closed_by_server()) {
    client.receive_until(1, 10.0);
    const auto got = client.take();
    if (got.empty()) break;
    for (const auto& m : got)
      if (m.header.type == "TRANSFORM") {
        last_x = test::unpack(m).matrix(0, 3);
        ++transforms;
      }
  }
  EXPECT_EQ(last_x, kPublished);
  // Every publish was either sent or replaced by a newer one before it went out.
  EXPECT_EQ(transforms + server.stats().messages_replaced, static_cast<std::size_t>(kPublished) + 1);
}

TEST(IgtlServer, ResetClientDroppedOthersKeepReceiving) {
  Logged logged;
  Server server(test_options(), logged.log());
  TestClient a(server.port());
  TestClient b(server.port());
  ASSERT_TRUE(a.connected() && b.connected());
  ASSERT_TRUE(wait_until([&] { return server.clients() == 2; }));
  server.publish("T", transform_packet("T", 1.0));
  EXPECT_EQ(count_type(b.receive_until(1, 10.0), "TRANSFORM"), 1u);
  b.reset();  // as a killed process: TCP reset
  for (int i = 0; i < 50 && server.clients() == 2; ++i) {
    server.publish("T", transform_packet("T", i));
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ASSERT_TRUE(wait_until([&] { return server.clients() == 1; })) << logged.all();
  a.take();
  server.publish("T", transform_packet("T", 99.0));
  const auto& got = a.receive_until(1000, 1.0);
  double last_x = -1;
  for (const auto& m : got)
    if (m.header.type == "TRANSFORM") last_x = test::unpack(m).matrix(0, 3);
  EXPECT_EQ(last_x, 99.0);
  EXPECT_FALSE(a.closed_by_server());
}

TEST(IgtlServer, ClientNotReadingIsDroppedAfterTheSendTimeout) {
  Logged logged;
  ServerOptions o = test_options();
  o.send_timeout_s = 1.0;
  Server server(o, logged.log());
  TestClient stuck(server.port());  // never reads
  TestClient reader(server.port());
  ASSERT_TRUE(stuck.connected() && reader.connected());
  ASSERT_TRUE(wait_until([&] { return server.clients() == 2; }));
  std::atomic<bool> stop{false};
  std::atomic<std::size_t> images_read{0};
  std::thread reading([&] {
    while (!stop.load() && !reader.closed_by_server()) {
      reader.receive_until(1000000, 0.05);
      images_read += count_type(reader.take(), "IMAGE");
    }
  });
  std::vector<std::uint8_t> pixels(640 * 480 * 3, 128);
  for (int i = 0; i < 3000 && server.stats().clients_dropped == 0; ++i) {
    server.publish("Image_Reference", pack_image_rgb("Image_Reference", 640, 480, pixels.data(), wall_us()));
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  const std::size_t before = images_read.load();
  server.publish("Image_Reference", pack_image_rgb("Image_Reference", 640, 480, pixels.data(), wall_us()));
  EXPECT_TRUE(wait_until([&] { return images_read.load() > before; }));
  stop.store(true);
  reading.join();
  EXPECT_EQ(server.stats().clients_dropped, 1u) << logged.all();
  EXPECT_NE(logged.all().find("did not finish within"), std::string::npos) << logged.all();
  EXPECT_FALSE(reader.closed_by_server());
}

TEST(IgtlServer, GarbageClientDroppedWithTheReason) {
  Logged logged;
  Server server(test_options(), logged.log());
  TestClient web(server.port());
  ASSERT_TRUE(web.connected());
  const std::string get = "GET / HTTP/1.1\r\nHost: localhost\r\n\r\n..........................................";
  ASSERT_TRUE(web.send(std::vector<std::uint8_t>(get.begin(), get.end())));
  ASSERT_TRUE(wait_until([&] { return server.stats().clients_dropped == 1; })) << logged.all();
  EXPECT_NE(logged.all().find("header version"), std::string::npos) << logged.all();
  web.receive_until(1000, 1.0);
  EXPECT_TRUE(web.closed_by_server());
}

tool_pose_t pose(const std::string& tool, std::int64_t frame, bool valid, double x) {
  tool_pose_t p{};
  p.tool_name = tool;
  p.frame_parent = "Ndi";
  p.frame_child = "Tool";
  p.source = tool_pose_t::SOURCE_NDI;
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.translation() = Eigen::Vector3d(x, 2, 3);
  set_pose(p, X);
  p.status = valid ? tool_pose_t::STATUS_VALID : tool_pose_t::STATUS_MISSING;
  p.device_frame_number = frame;
  p.receive_time_wall_us = 1'764'633'600'000'000 + frame * 16667;
  return p;
}

TEST(IgtlBridge, PlusNamesTipsAndToolsNotSeen) {
  Logged logged;
  Server server(test_options(), logged.log());
  BridgeOptions bo;
  bo.tips_Tool_mm["pointer"] = Eigen::Vector3d(0, 0, -100);
  Bridge bridge(bo, server, logged.log());
  TestClient client(server.port());
  ASSERT_TRUE(client.connected());
  ASSERT_TRUE(wait_until([&] { return server.clients() == 1; }));
  bridge.on_pose(pose("reference", 1, false, 0));   // not seen: nothing
  bridge.on_pose(pose("pointer", 1, true, 10));
  bridge.on_pose(pose("a_tool_with_a_long_name", 1, true, 10));  // > 20 characters: reported, not sent
  const auto& got = client.receive_until(2, 10.0);
  client.receive_until(1000, 0.3);
  std::vector<std::string> names;
  for (const auto& m : got)
    if (m.header.type == "TRANSFORM") names.push_back(m.header.device_name);
  EXPECT_EQ(names, (std::vector<std::string>{"PointerToTracker", "PointerTipToTracker"}));
  const auto tip = test::unpack(got[1]);
  EXPECT_TRUE(tip.crc_ok);
  EXPECT_NEAR(tip.matrix(0, 3), 10.0, 1e-5);
  EXPECT_NEAR(tip.matrix(2, 3), 3.0 - 100.0, 1e-4);
  EXPECT_EQ(tip.wall_us, pose("pointer", 1, true, 10).receive_time_wall_us);
  EXPECT_EQ(bridge.stats().not_seen, 1u);
  EXPECT_EQ(bridge.stats().unnamed, 1u);
  EXPECT_NE(logged.all().find("a_tool_with_a_long_name: not sent"), std::string::npos) << logged.all();
}

TEST(IgtlBridge, OneTdataPerTrackerFrameWithTheValidTools) {
  Logged logged;
  Server server(test_options(), logged.log());
  Bridge bridge({}, server, logged.log());
  TestClient client(server.port());
  ASSERT_TRUE(client.connected());
  ASSERT_TRUE(client.send(test::start_tdata_request(16)));
  ASSERT_TRUE(wait_until([&] { return server.stats().requests_handled == 1; }));
  // The next TDATA's element names (each is awaited before the next is made: a client
  // keeps only the latest TDATA).
  auto next_tdata = [&] {
    std::vector<std::string> names;
    while (names.empty() && !client.closed_by_server()) {
      client.receive_until(1, 10.0);
      const auto got = client.take();
      if (got.empty()) break;
      for (const auto& m : got)
        if (m.header.type == "TDATA")
          for (const auto& [name, matrix] : test::unpack(m).tdata) names.push_back(name);
    }
    return names;
  };
  const std::vector<std::string> both = {"PointerToTracker", "ReferenceToTracker"};
  bridge.on_pose(pose("pointer", 1, true, 1));
  bridge.on_pose(pose("reference", 1, true, 1));
  bridge.on_pose(pose("pointer", 2, false, 2));  // frame 2 starts: frame 1 is complete
  EXPECT_EQ(next_tdata(), both);
  bridge.on_pose(pose("reference", 2, true, 2));  // as many poses as frame 1: complete at once
  EXPECT_EQ(next_tdata(), std::vector<std::string>{"ReferenceToTracker"});  // pointer not seen
  bridge.on_pose(pose("pointer", 3, true, 3));
  bridge.on_pose(pose("reference", 3, true, 3));
  EXPECT_EQ(next_tdata(), both);
  EXPECT_EQ(bridge.stats().tdata, 3u);
}

TEST(IgtlBridge, CameraFrameBecomesDownscaledRgbImage) {
  Logged logged;
  Server server(test_options(), logged.log());
  BridgeOptions bo;
  bo.image_downscale = 2;
  Bridge bridge(bo, server, logged.log());
  TestClient client(server.port());
  ASSERT_TRUE(client.connected());
  ASSERT_TRUE(wait_until([&] { return server.clients() == 1; }));
  cv::Mat bgr(8, 12, CV_8UC3, cv::Scalar(255, 0, 0));  // blue in OpenCV's BGR
  std::vector<std::uint8_t> png;
  ASSERT_TRUE(cv::imencode(".png", bgr, png));
  image_frame_t frame{};
  frame.camera_name = "endo";
  frame.capture_time_wall_us = 1'764'633'600'000'123;
  frame.width = 12;
  frame.height = 8;
  frame.encoding = image_frame_t::ENCODING_PNG;
  frame.size = static_cast<std::int32_t>(png.size());
  frame.data = png;
  bridge.on_frame(frame);
  const auto& got = client.receive_until(1, 10.0);
  ASSERT_EQ(count_type(got, "IMAGE", "Image_Reference"), 1u);
  const auto u = test::unpack(got[0]);
  ASSERT_TRUE(u.crc_ok);
  EXPECT_EQ(u.width, 6);
  EXPECT_EQ(u.height, 4);
  EXPECT_EQ(u.components, 3);
  ASSERT_EQ(u.pixels.size(), 6u * 4u * 3u);
  EXPECT_EQ(u.pixels[0], 0);    // R
  EXPECT_EQ(u.pixels[2], 255);  // B
  EXPECT_EQ(u.wall_us, frame.capture_time_wall_us);
  image_frame_t broken = frame;
  broken.data.assign(broken.data.size(), 0);
  bridge.on_frame(broken);
  EXPECT_TRUE(wait_until([&] { return bridge.stats().frames_undecodable == 1; }));
  EXPECT_NE(logged.all().find("cannot be decoded"), std::string::npos);
}

Packet organ_packet(double phase, const std::string& surface = "organ") {
  std::string name, why;
  return *polydata_from_surface(test::sphere_surface(surface, 4, 6, phase, wall_us()), name, why);
}

TEST(IgtlServer, GetPolydataAnsweredFromTheLatestAgainAndAgain) {
  Logged logged;
  Server server(test_options(), logged.log());
  server.publish_polydata("Organ", organ_packet(0.0));  // before the client connects: only GET_POLYDATA gets it
  server.publish_polydata("Organ", organ_packet(1.0));
  TestClient client(server.port());
  ASSERT_TRUE(client.connected()) << client.why();
  ASSERT_TRUE(client.send(test::slicer_v2_status()));
  for (int i = 0; i < 5; ++i) {  // a client asking repeatedly gets an answer each time (v1 and v2 headers)
    ASSERT_TRUE(client.send(test::named_request("GET_POLYDATA", "Organ", i % 2 == 0 ? 1 : 2)));
    const auto& got = client.receive_until(1, 10.0);
    ASSERT_EQ(count_type(got, "POLYDATA", "Organ"), 1u) << "request " << i << "\n" << logged.all();
    const auto u = test::unpack(got[0]);
    ASSERT_TRUE(u.crc_ok);
    const surface_mesh_t latest = test::sphere_surface("organ", 4, 6, 1.0, 0);  // the second mesh published, not the first
    ASSERT_EQ(u.points_mm.size(), latest.positions_mm.size());
    for (std::size_t v = 0; v < latest.positions_mm.size(); ++v) EXPECT_EQ(u.points_mm[v][0], latest.positions_mm[v][0]) << v;
    client.take();
  }
  EXPECT_EQ(server.stats().polydata_unknown, 0u);
}

TEST(IgtlServer, GetPolydataForAnUnknownNameGetsAnEmptyPolydata) {
  Logged logged;
  Server server(test_options(), logged.log());
  TestClient client(server.port());
  ASSERT_TRUE(client.connected()) << client.why();
  ASSERT_TRUE(client.send(test::named_request("GET_POLYDATA", "Tumour")));  // nothing published yet
  auto got = client.receive_until(1, 10.0);
  ASSERT_EQ(count_type(got, "POLYDATA", "Tumour"), 1u) << logged.all();
  auto u = test::unpack(got[0]);
  EXPECT_TRUE(u.empty_body);
  EXPECT_TRUE(u.crc_ok);
  EXPECT_GT(u.wall_us, 1'700'000'000'000'000);  // UTC now
  EXPECT_NE(logged.all().find("GET_POLYDATA 'Tumour': no such surface (none yet)"), std::string::npos) << logged.all();
  client.take();

  server.publish_polydata("Organ", organ_packet(0.5));
  got = client.receive_until(1, 10.0);  // pushed to the connected client
  ASSERT_EQ(count_type(got, "POLYDATA", "Organ"), 1u);
  client.take();
  ASSERT_TRUE(client.send(test::named_request("GET_POLYDATA", "Cut")));
  got = client.receive_until(1, 10.0);
  ASSERT_EQ(count_type(got, "POLYDATA", "Cut"), 1u);
  EXPECT_TRUE(test::unpack(got[0]).empty_body);
  EXPECT_NE(logged.all().find("GET_POLYDATA 'Cut': no such surface (have Organ)"), std::string::npos) << logged.all();
  client.take();
  // Without a name: every surface there is.
  server.publish_polydata("Tumour", organ_packet(0.7, "tumour"));
  client.receive_until(1, 10.0);
  client.take();
  ASSERT_TRUE(client.send(test::named_request("GET_POLYDATA", "")));
  got = client.receive_until(2, 10.0);
  EXPECT_EQ(count_type(got, "POLYDATA", "Organ"), 1u);
  EXPECT_EQ(count_type(got, "POLYDATA", "Tumour"), 1u);
  EXPECT_EQ(server.stats().polydata_unknown, 2u);
  EXPECT_EQ(server.stats().clients_dropped, 0u);
}

// Receives until a message of `type` named `name` arrives (or 10 s pass); returns all received.
std::vector<Message> receive_through(TestClient& client, const std::string& type, const std::string& name) {
  std::vector<Message> got;
  for (int i = 0; i < 200 && count_type(got, type, name) == 0 && !client.closed_by_server(); ++i) {
    client.receive_until(1, 0.05);
    for (auto& m : client.take()) got.push_back(std::move(m));
  }
  return got;
}

TEST(IgtlServer, StopAndStartPolydataPerNameAnsweredWithRts) {
  Logged logged;
  Server server(test_options(), logged.log());
  server.publish_polydata("Organ", organ_packet(0.0));
  server.publish_polydata("Tumour", organ_packet(0.1, "tumour"));
  TestClient client(server.port());
  ASSERT_TRUE(client.connected()) << client.why();
  ASSERT_TRUE(wait_until([&] { return server.clients() == 1; }));
  auto expect_rts = [&](const std::vector<Message>& got, const std::string& name) {
    ASSERT_EQ(count_type(got, "RTS_POLYDATA", name), 1u) << logged.all();
    for (const auto& m : got)
      if (m.header.type == "RTS_POLYDATA") {
        const auto u = test::unpack(m);
        EXPECT_TRUE(u.crc_ok);
        EXPECT_EQ(u.status_code, 0);  // success
      }
  };
  // Stop the organ only: answered, then only the tumour is pushed.
  ASSERT_TRUE(client.send(test::named_request("STP_POLYDATA", "Organ")));
  expect_rts(receive_through(client, "RTS_POLYDATA", "Organ"), "Organ");
  server.publish_polydata("Organ", organ_packet(0.2));
  server.publish_polydata("Tumour", organ_packet(0.3, "tumour"));
  server.publish("T", transform_packet("T", 1.0));  // a marker after both surfaces
  auto got = receive_through(client, "TRANSFORM", "T");
  EXPECT_EQ(count_type(got, "POLYDATA", "Organ"), 0u);
  EXPECT_EQ(count_type(got, "POLYDATA", "Tumour"), 1u);
  // GET_POLYDATA is still answered for a stopped surface.
  ASSERT_TRUE(client.send(test::named_request("GET_POLYDATA", "Organ")));
  EXPECT_EQ(count_type(receive_through(client, "POLYDATA", "Organ"), "POLYDATA", "Organ"), 1u);
  // Stop every surface (no name), then start them all: the start sends the latest at once.
  ASSERT_TRUE(client.send(test::named_request("STP_POLYDATA", "", 2)));
  expect_rts(receive_through(client, "RTS_POLYDATA", ""), "");
  server.publish_polydata("Organ", organ_packet(0.4));
  server.publish_polydata("Tumour", organ_packet(0.5, "tumour"));
  server.publish("T", transform_packet("T", 2.0));
  got = receive_through(client, "TRANSFORM", "T");
  EXPECT_EQ(count_type(got, "POLYDATA"), 0u);
  ASSERT_TRUE(client.send(test::named_request("STT_POLYDATA", "")));
  got = receive_through(client, "RTS_POLYDATA", "");
  expect_rts(got, "");
  for (int i = 0; i < 2 && (count_type(got, "POLYDATA", "Organ") == 0 || count_type(got, "POLYDATA", "Tumour") == 0); ++i)
    for (auto& m : receive_through(client, "POLYDATA", count_type(got, "POLYDATA", "Organ") == 0 ? "Organ" : "Tumour")) got.push_back(std::move(m));
  EXPECT_EQ(count_type(got, "POLYDATA", "Organ"), 1u);
  EXPECT_EQ(count_type(got, "POLYDATA", "Tumour"), 1u);
  for (const auto& m : got)
    if (m.header.type == "POLYDATA" && m.header.device_name == "Organ") {  // the latest published, not the one before the stop
      const auto u = test::unpack(m);
      const surface_mesh_t latest = test::sphere_surface("organ", 4, 6, 0.4, 0);
      ASSERT_EQ(u.points_mm.size(), latest.positions_mm.size());
      EXPECT_EQ(u.points_mm[1][0], latest.positions_mm[1][0]);
    }
  server.publish_polydata("Organ", organ_packet(0.6));  // pushed again
  EXPECT_EQ(count_type(receive_through(client, "POLYDATA", "Organ"), "POLYDATA", "Organ"), 1u);
  EXPECT_NE(logged.all().find("stopped surfaces (Organ)"), std::string::npos) << logged.all();
  EXPECT_EQ(server.stats().requests_handled, 4u);
  EXPECT_EQ(server.stats().clients_dropped, 0u);
}

TEST(IgtlBridge, SurfacesBecomePolydataPerNameAndBadOnesAreReported) {
  Logged logged;
  Server server(test_options(), logged.log());
  Bridge bridge(BridgeOptions{}, server, logged.log());
  TestClient client(server.port());
  ASSERT_TRUE(client.connected());
  ASSERT_TRUE(wait_until([&] { return server.clients() == 1; }));
  const std::int64_t t = 1'764'633'600'000'777;
  bridge.on_surface(test::sphere_surface("organ", 5, 8, 0.1, t));
  bridge.on_surface(test::sphere_surface("tumour", 3, 4, 0.0, t));
  const auto& got = client.receive_until(2, 10.0);
  ASSERT_EQ(count_type(got, "POLYDATA", "Organ"), 1u) << logged.all();
  ASSERT_EQ(count_type(got, "POLYDATA", "Tumour"), 1u);
  for (const auto& m : got) {
    const auto u = test::unpack(m);
    ASSERT_TRUE(u.crc_ok);
    EXPECT_EQ(u.wall_us, t);
    EXPECT_EQ(u.points_mm.size(), m.header.device_name == "Organ" ? 2u + 4u * 8u : 2u + 2u * 4u);
  }
  client.take();
  surface_mesh_t in_model = test::sphere_surface("cut", 3, 4, 0.0, t);
  in_model.frame_name = "Model";
  bridge.on_surface(in_model);
  ASSERT_TRUE(wait_until([&] { return bridge.stats().surfaces_rejected == 1; }));
  bridge.on_surface(in_model);
  ASSERT_TRUE(wait_until([&] { return bridge.stats().surfaces_rejected == 2; }));
  const std::string log = logged.all();
  EXPECT_NE(log.find("surface 'cut' (ARNAV_SURFACE_cut): not sent: its vertices are in frame 'Model'"), std::string::npos) << log;
  EXPECT_EQ(log.find("not sent"), log.rfind("not sent"));  // reported once
  ASSERT_TRUE(client.send(test::named_request("GET_POLYDATA", "Organ")));
  EXPECT_EQ(count_type(client.receive_until(1, 10.0), "POLYDATA", "Organ"), 1u);
  EXPECT_EQ(bridge.stats().polydata, 2u);
}

}  // namespace
}  // namespace arnav::igtl
