// The OpenIGTLink framing read by hand (header v1/v2, extended header, stream reader), the
// CRC against libopenigtlink's, PLUS naming, UTC time stamps, and packed messages read back
// with libopenigtlink.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include <igtlMessageHeader.h>
#include <igtl_util.h>

#include "host/igtl/bridge.hpp"
#include "host/igtl/messages.hpp"
#include "host/igtl/test/test_client.hpp"
#include "host/igtl/wire.hpp"

namespace arnav::igtl {
namespace {

std::vector<Message> read_all(const std::vector<std::uint8_t>& stream, std::size_t chunk, StreamReader& reader) {
  std::vector<Message> out;
  for (std::size_t pos = 0; pos < stream.size(); pos += chunk) {
    reader.feed(std::span<const std::uint8_t>(stream.data() + pos, std::min(chunk, stream.size() - pos)));
    while (auto m = reader.next()) out.push_back(std::move(*m));
  }
  return out;
}

std::vector<std::uint8_t> concat(std::initializer_list<std::vector<std::uint8_t>> parts) {
  std::vector<std::uint8_t> out;
  for (const auto& p : parts) out.insert(out.end(), p.begin(), p.end());
  return out;
}

TEST(IgtlWire, HeaderRoundTrip) {
  const Header h{2, "STT_TDATA", "SlicerConnector", 0x0123456789abcdefull, 44, 0xfedcba9876543210ull};
  const auto bytes = test::raw_header_bytes(h);
  ASSERT_EQ(bytes.size(), kHeaderSize);
  EXPECT_EQ(bytes[0], 0);
  EXPECT_EQ(bytes[1], 2);  // big endian
  std::string why;
  const auto back = parse_header(std::span<const std::uint8_t, kHeaderSize>(bytes.data(), kHeaderSize), 1000, why);
  ASSERT_TRUE(back) << why;
  EXPECT_EQ(back->version, 2);
  EXPECT_EQ(back->type, "STT_TDATA");
  EXPECT_EQ(back->device_name, "SlicerConnector");
  EXPECT_EQ(back->timestamp, h.timestamp);
  EXPECT_EQ(back->body_size, 44u);
  EXPECT_EQ(back->crc, h.crc);
}

TEST(IgtlWire, HeaderRejectsWhatIsNotOpenIgtlink) {
  std::string why;
  auto parse = [&](const std::vector<std::uint8_t>& b) {
    why.clear();
    return parse_header(std::span<const std::uint8_t, kHeaderSize>(b.data(), kHeaderSize), 1000, why);
  };
  std::vector<std::uint8_t> http(kHeaderSize, 'A');
  const std::string get = "GET / HTTP/1.1\r\n";
  std::copy(get.begin(), get.end(), http.begin());
  EXPECT_FALSE(parse(http));
  EXPECT_NE(why.find("header version"), std::string::npos) << why;

  auto bad_type = test::raw_header_bytes({1, "TRANS\x01", "x", 0, 0, 0});
  EXPECT_FALSE(parse(bad_type));
  EXPECT_NE(why.find("not printable"), std::string::npos) << why;

  auto empty_type = test::raw_header_bytes({1, "", "x", 0, 0, 0});
  EXPECT_FALSE(parse(empty_type));

  auto junk_after_nul = test::raw_header_bytes({1, "STATUS", "x", 0, 0, 0});
  junk_after_nul[2 + 8] = 'Z';  // after the type's NUL
  EXPECT_FALSE(parse(junk_after_nul));

  auto too_big = test::raw_header_bytes({1, "IMAGE", "x", 0, 1001, 0});
  EXPECT_FALSE(parse(too_big));
  EXPECT_NE(why.find("1001 bytes"), std::string::npos) << why;
}

TEST(IgtlWire, CrcAgreesWithLibopenigtlink) {
  std::mt19937 rng(7);
  for (std::size_t size : {0u, 1u, 7u, 58u, 1000u, 65537u}) {
    std::vector<std::uint8_t> data(size);
    for (auto& b : data) b = static_cast<std::uint8_t>(rng());
    EXPECT_EQ(body_crc(data), crc64(data.data(), data.size(), 0ull)) << size << " bytes";
  }
}

TEST(IgtlWire, ReaderFramesSlicerV2StatusThenRequestsInAnyChunking) {
  const auto stream = concat({test::slicer_v2_status(), test::start_tdata_request(16), test::request("GET_STATUS", 2),
                              test::request("STP_TDATA")});
  for (std::size_t chunk = 1; chunk <= stream.size(); ++chunk) {
    StreamReader reader({"STT_TDATA", "STP_TDATA", "GET_STATUS"}, 4096, 1 << 20);
    const auto messages = read_all(stream, chunk, reader);
    ASSERT_FALSE(reader.failed()) << reader.error();
    ASSERT_EQ(messages.size(), 4u) << "chunk " << chunk;
    EXPECT_EQ(messages[0].header.type, "STATUS");
    EXPECT_EQ(messages[0].header.version, 2);
    EXPECT_FALSE(messages[0].body_kept);  // skipped, not stored
    EXPECT_EQ(messages[1].header.type, "STT_TDATA");
    ASSERT_TRUE(messages[1].body_kept);
    EXPECT_EQ(body_crc(messages[1].body), messages[1].header.crc);
    EXPECT_EQ(messages[2].header.type, "GET_STATUS");
    EXPECT_EQ(messages[3].header.type, "STP_TDATA");
    EXPECT_EQ(reader.messages_skipped(), 1u);
  }
}

TEST(IgtlWire, V2ContentExcludesExtendedHeaderAndMetadata) {
  const auto status = test::slicer_v2_status();
  StreamReader reader({"STATUS"}, 4096, 4096);
  reader.feed(status);
  auto m = reader.next();
  ASSERT_TRUE(m);
  std::string why;
  const auto content = body_content(m->header, m->body, why);
  ASSERT_TRUE(content) << why;
  EXPECT_EQ(content->size(), 2u + 8u + 20u + 1u);  // code, subcode, error name, empty string
  EXPECT_EQ((*content)[1], 1);                        // STATUS_OK
  m->body[1] = 200;                                   // extended header larger than the body
  EXPECT_FALSE(body_content(m->header, m->body, why));
  EXPECT_NE(why.find("does not fit"), std::string::npos) << why;
  Header v1 = m->header;
  v1.version = 1;
  EXPECT_EQ(body_content(v1, m->body, why)->size(), m->body.size());
}

TEST(IgtlWire, ReaderSkipsLargeUnhandledBodiesAndRefusesLargeRequests) {
  Header image{1, "IMAGE", "Image_Reference", 0, 300000, 0};
  auto stream = test::raw_header_bytes(image);
  stream.resize(stream.size() + 300000, 0xab);
  const auto after = test::request("GET_STATUS");
  stream.insert(stream.end(), after.begin(), after.end());
  StreamReader reader({"GET_STATUS"}, 4096, 1 << 20);
  const auto messages = read_all(stream, 4000, reader);
  ASSERT_EQ(messages.size(), 2u);
  EXPECT_TRUE(messages[0].body.empty());
  EXPECT_EQ(messages[1].header.type, "GET_STATUS");

  StreamReader strict({"IMAGE"}, 4096, 1 << 20);
  strict.feed(stream);
  EXPECT_TRUE(strict.failed());
  EXPECT_NE(strict.error().find("limit of 4096"), std::string::npos) << strict.error();
  strict.feed(after);  // stays failed
  EXPECT_FALSE(strict.next());
}

TEST(IgtlNaming, PlusNames) {
  std::string why;
  EXPECT_EQ(plus_frame_name("pointer"), "Pointer");
  EXPECT_EQ(plus_frame_name("stylus_tip"), "StylusTip");
  EXPECT_EQ(transform_device_name("pointer", "Ref", why).value_or(""), "PointerToReference");
  EXPECT_EQ(transform_device_name("reference", "Ndi", why).value_or(""), "ReferenceToTracker");
  EXPECT_EQ(transform_device_name("board", "Cam", why).value_or(""), "BoardToCamera");
  EXPECT_FALSE(transform_device_name("ultrasound_probe", "Ref", why));  // UltrasoundProbeToReference: 26
  EXPECT_NE(why.find("--name"), std::string::npos) << why;
  EXPECT_FALSE(transform_device_name("__", "Ref", why));
}

TEST(IgtlTime, WallClockToIgtlAndBack) {
  for (std::int64_t us : {0ll, 1ll, 999999ll, 1'764'633'600'123'456ll}) {
    const std::uint64_t t = igtl_time_from_wall_us(us);
    EXPECT_EQ(t >> 32, static_cast<std::uint64_t>(us / 1000000));
    EXPECT_EQ(wall_us_from_igtl_time(t), us);
  }
}

TEST(IgtlMessages, TransformReadBackByLibopenigtlink) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.rotate(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()));
  X.translation() = Eigen::Vector3d(12.5, -300.25, -1500.0);
  const std::int64_t t_us = 1'764'633'600'654'321;
  const Packet p = pack_transform("PointerToReference", X, t_us);
  StreamReader reader({"TRANSFORM"}, 1024, 1024);
  reader.feed(*p);
  const auto m = reader.next();
  ASSERT_TRUE(m);
  EXPECT_EQ(m->header.version, 1);
  EXPECT_EQ(m->header.crc, body_crc(m->body));
  const auto u = test::unpack(*m);
  ASSERT_TRUE(u.crc_ok);
  EXPECT_EQ(u.device_name, "PointerToReference");
  EXPECT_EQ(u.wall_us, t_us);
  EXPECT_LT((u.matrix - X.matrix()).cwiseAbs().maxCoeff(), 1e-4);  // float32 on the wire
}

TEST(IgtlMessages, TdataStatusAndImageReadBack) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.translation() = Eigen::Vector3d(1, 2, 3);
  StreamReader reader({"TDATA", "STATUS", "IMAGE"}, 1 << 20, 1 << 20);
  reader.feed(*pack_tdata("ARNav", {{"PointerToTracker", X}, {"ReferenceToTracker", Eigen::Isometry3d::Identity()}}, 5));
  reader.feed(*pack_status("ARNav", 1, "", 6));
  const std::vector<std::uint8_t> rgb = {255, 0, 0, 0, 255, 0, 0, 0, 255, 10, 20, 30, 40, 50, 60, 70, 80, 90};
  reader.feed(*pack_image_rgb("Image_Reference", 3, 2, rgb.data(), 7));
  auto tdata = test::unpack(*reader.next());
  ASSERT_TRUE(tdata.crc_ok);
  ASSERT_EQ(tdata.tdata.size(), 2u);
  EXPECT_EQ(tdata.tdata[0].first, "PointerToTracker");
  EXPECT_DOUBLE_EQ(tdata.tdata[0].second(2, 3), 3.0);
  EXPECT_EQ(tdata.tdata[1].first, "ReferenceToTracker");
  auto status = test::unpack(*reader.next());
  ASSERT_TRUE(status.crc_ok);
  EXPECT_EQ(status.status_code, 1);
  auto image = test::unpack(*reader.next());
  ASSERT_TRUE(image.crc_ok);
  EXPECT_EQ(image.width, 3);
  EXPECT_EQ(image.height, 2);
  EXPECT_EQ(image.components, 3);
  EXPECT_EQ(image.pixels, rgb);
  EXPECT_EQ(image.wall_us, 7);
}

TEST(IgtlMessages, PolydataReadBackByLibopenigtlinkWithCrc) {
  const std::vector<std::array<float, 3>> points = {{0, 0, 0}, {10.5f, 0, 0}, {0, 20.25f, 0}, {0, 0, -1400.125f}};
  const std::vector<std::array<std::uint32_t, 3>> triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  const std::int64_t t = 1'764'633'600'123'456;
  const Packet packet = pack_polydata("Organ", points, triangles, t);
  StreamReader reader({"POLYDATA"}, 1 << 20, 1 << 20);
  reader.feed(*packet);
  const auto m = reader.next();
  ASSERT_TRUE(m);
  EXPECT_EQ(m->header.type, "POLYDATA");
  EXPECT_EQ(m->header.device_name, "Organ");
  const auto u = test::unpack(*m);
  ASSERT_TRUE(u.crc_ok);
  EXPECT_FALSE(u.empty_body);
  EXPECT_EQ(u.wall_us, t);
  EXPECT_EQ(u.points_mm, points);
  ASSERT_EQ(u.polygons.size(), triangles.size());
  for (std::size_t i = 0; i < triangles.size(); ++i)
    EXPECT_EQ(u.polygons[i], std::vector<std::uint32_t>(triangles[i].begin(), triangles[i].end())) << "triangle " << i;
  EXPECT_EQ(u.other_cells, 0u);

  Message damaged = *m;  // one bit of one coordinate: the library's CRC check refuses it
  damaged.body[damaged.body.size() / 2] ^= 0x04;
  EXPECT_FALSE(test::unpack(damaged).crc_ok);
}

TEST(IgtlMessages, EmptyPolydataIsTheNotAvailableAnswer) {
  const Packet packet = pack_empty("POLYDATA", "Tumour", 1'764'633'600'000'000);
  ASSERT_EQ(packet->size(), kHeaderSize);
  std::string why;
  const auto h = parse_header(std::span<const std::uint8_t, kHeaderSize>(packet->data(), kHeaderSize), 1 << 20, why);
  ASSERT_TRUE(h) << why;
  EXPECT_EQ(h->type, "POLYDATA");
  EXPECT_EQ(h->device_name, "Tumour");
  EXPECT_EQ(h->body_size, 0u);
  EXPECT_EQ(h->crc, body_crc({}));
  EXPECT_EQ(wall_us_from_igtl_time(h->timestamp), 1'764'633'600'000'000);
  // libopenigtlink reads the header as a complete POLYDATA header.
  auto header = ::igtl::MessageHeader::New();
  header->InitPack();
  std::memcpy(header->GetPackPointer(), packet->data(), kHeaderSize);
  header->Unpack();
  EXPECT_STREQ(header->GetDeviceType(), "POLYDATA");
  EXPECT_EQ(header->GetBodySizeToRead(), 0u);
}

TEST(IgtlSurface, HostMeshBecomesPolydataInReference) {
  const surface_mesh_t organ = test::sphere_surface("organ", 6, 8, 0.3, 1'764'633'600'000'500);
  std::string name, why;
  const auto packet = polydata_from_surface(organ, name, why);
  ASSERT_TRUE(packet) << why;
  EXPECT_EQ(name, "Organ");
  StreamReader reader({"POLYDATA"}, 1 << 20, 1 << 20);
  reader.feed(**packet);
  const auto u = test::unpack(*reader.next());
  ASSERT_TRUE(u.crc_ok);
  EXPECT_EQ(u.wall_us, organ.model_step_wall_us);  // the model step's UTC time, not the publish time
  ASSERT_EQ(u.points_mm.size(), organ.positions_mm.size());
  for (std::size_t i = 0; i < u.points_mm.size(); ++i)
    for (int k = 0; k < 3; ++k) EXPECT_EQ(u.points_mm[i][static_cast<std::size_t>(k)], organ.positions_mm[i][static_cast<std::size_t>(k)]);
  ASSERT_EQ(u.polygons.size(), organ.triangles.size());
  EXPECT_EQ(u.polygons[5], std::vector<std::uint32_t>(organ.triangles[5].begin(), organ.triangles[5].end()));

  EXPECT_TRUE(polydata_from_surface(test::sphere_surface("tumour2", 3, 4, 0, 1), name, why));
  EXPECT_EQ(name, "Tumour2");
  EXPECT_TRUE(polydata_from_surface(test::sphere_surface("cut", 3, 4, 0, 1), name, why));
  EXPECT_EQ(name, "Cut");
}

TEST(IgtlSurface, InconsistentMeshesAreRefusedWithTheReason) {
  const surface_mesh_t good = test::sphere_surface("organ", 3, 4, 0, 1);
  std::string name, why;
  const auto refused = [&](surface_mesh_t m, const std::string& expect) {
    why.clear();
    const bool ok = polydata_from_surface(m, name, why).has_value();
    EXPECT_FALSE(ok) << expect;
    EXPECT_NE(why.find(expect), std::string::npos) << why;
  };
  surface_mesh_t m = good;
  m.frame_name = "Model";
  refused(m, "frame 'Model'");
  m = good;
  m.name = "a_surface_with_a_very_long_name";
  refused(m, "1..20 characters");
  m = good;
  m.num_vertices += 1;
  refused(m, "disagree");
  m = good;
  m.triangles[2][1] = m.num_vertices;
  refused(m, "triangle 2");
  m = good;
  m.triangles[0][0] = -1;
  refused(m, "triangle 0");
  m = good;
  m.positions_mm[3][2] = std::nanf("");
  refused(m, "vertex 3");
  m = good;
  m.positions_mm[1].resize(2);
  refused(m, "vertex 1");
}

}  // namespace
}  // namespace arnav::igtl
