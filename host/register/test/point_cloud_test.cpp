// Point-cloud readers: every format, normals, ids, and the errors that name file and line.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <cmath>
#include <cstdlib>
#include <vector>
#include <string>

#include "arnav/point_cloud_t.hpp"
#include "host/register/point_cloud.hpp"
#include "host/mesh/load_error.hpp"
#include "protocol/testing/error_of.hpp"

using namespace arnav::host;

namespace {

std::string error_of(const std::string& text, const std::string& format, const std::string& source = "cloud") {
  return arnav::testing::error_of<LoadError>([&] { parse_point_cloud(text, source + "." + format, format); });
}

}  // namespace

TEST(PointCloud, XyzSpaceAndCommaSeparated) {
  const PointCloud a = parse_point_cloud("# swab\n1 2 3\n4\t5  6\n\n7 8 9\n", "a.xyz", "xyz");
  ASSERT_EQ(a.size(), 3);
  EXPECT_DOUBLE_EQ(a.points_mm(1, 1), 5.0);
  EXPECT_FALSE(a.has_normals());
  EXPECT_EQ(a.lines, (std::vector<int>{2, 3, 5}));
  const PointCloud b = parse_point_cloud("1.5,2,3\n-4e1, 5 ,6\r\n", "b.csv", "csv");
  ASSERT_EQ(b.size(), 2);
  EXPECT_DOUBLE_EQ(b.points_mm(0, 1), -40.0);
}

TEST(PointCloud, NormalsAreNormalised) {
  const PointCloud c = parse_point_cloud("0 0 0 0 0 2\n1 0 0 3 0 4\n", "n.txt", "txt");
  ASSERT_TRUE(c.has_normals());
  EXPECT_NEAR(c.normals(2, 0), 1.0, 1e-15);
  EXPECT_NEAR(c.normals(0, 1), 0.6, 1e-15);
}

TEST(PointCloud, HeaderWithIdsAndColumnOrder) {
  const PointCloud c = parse_point_cloud("id,z,y,x\n7,3,2,1\n9,6,5,4\n", "h.csv", "csv");
  ASSERT_EQ(c.size(), 2);
  EXPECT_DOUBLE_EQ(c.points_mm(0, 0), 1.0);
  EXPECT_DOUBLE_EQ(c.points_mm(2, 1), 6.0);
  EXPECT_EQ(c.ids, (std::vector<long long>{7, 9}));
}

TEST(PointCloud, TableErrorsNameFileAndLine) {
  EXPECT_NE(error_of("1 2 3\n4 5 nan\n", "xyz").find("cloud.xyz:2:"), std::string::npos);
  EXPECT_NE(error_of("1 2 3\n4 5 inf\n", "xyz").find("not finite"), std::string::npos);
  EXPECT_NE(error_of("1 2 3\n4 5\n", "xyz").find("cloud.xyz:2: expected 3 fields"), std::string::npos);
  EXPECT_NE(error_of("1 2 3 4\n", "xyz").find("cloud.xyz:1: expected 3 numbers"), std::string::npos);
  EXPECT_NE(error_of("1 2 abc\n", "xyz").find("not a number"), std::string::npos);
  EXPECT_NE(error_of("1,,3\n", "csv").find("cloud.csv:1:"), std::string::npos);
  EXPECT_NE(error_of("a,b,c\n1,2,3\n", "csv").find("does not name the columns"), std::string::npos);
  EXPECT_NE(error_of("x,y,z,nx\n1,2,3,4\n", "csv").find("part of the normal"), std::string::npos);
  EXPECT_NE(error_of("1 2 3 0 0 0\n", "xyz").find("zero-length normal"), std::string::npos);
  EXPECT_NE(error_of("1 2 3\n", "las").find("unknown point-cloud format"), std::string::npos);
}

TEST(PointCloud, EmptyFileIsAnEmptyCloud) {
  EXPECT_EQ(parse_point_cloud("# nothing\n\n", "e.xyz", "xyz").size(), 0);
}

TEST(PointCloud, PlyAscii) {
  const std::string ply =
      "ply\nformat ascii 1.0\ncomment made by hand\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
      "property float nx\nproperty float ny\nproperty float nz\nproperty uchar red\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "1 2 3 0 0 1 255\n4 5 6 0 2 0 0\n3 0 1 1\n";
  const PointCloud c = parse_point_cloud(ply, "a.ply", "ply");
  ASSERT_EQ(c.size(), 2);
  ASSERT_TRUE(c.has_normals());
  EXPECT_DOUBLE_EQ(c.points_mm(2, 1), 6.0);
  EXPECT_DOUBLE_EQ(c.normals(1, 1), 1.0);
  EXPECT_EQ(c.lines, (std::vector<int>{15, 16}));
  EXPECT_NE(error_of("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 5\n", "ply")
                .find("cloud.ply:9:"),
            std::string::npos);
  EXPECT_NE(error_of("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n", "ply")
                .find("truncated"),
            std::string::npos);
  EXPECT_NE(error_of("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n", "ply").find("no scalar x, y and z"),
            std::string::npos);
  EXPECT_NE(error_of("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 nan 3\n", "ply")
                .find("cloud.ply:8: vertex 0 has a non-finite y"),
            std::string::npos);
}

// Big-endian files (some scanners write them) read through the same reader.
TEST(PointCloud, PlyBinaryBigEndian) {
  std::string ply = "ply\nformat binary_big_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
  for (float v : {1.5f, -2.0f, 40.0f}) {
    unsigned char b[4];
    std::memcpy(b, &v, 4);
    for (int i = 3; i >= 0; --i) ply.push_back(static_cast<char>(b[i]));
  }
  const PointCloud c = parse_point_cloud(ply, "be.ply", "ply");
  ASSERT_EQ(c.size(), 1);
  EXPECT_DOUBLE_EQ(c.points_mm(0, 0), 1.5);
  EXPECT_DOUBLE_EQ(c.points_mm(1, 0), -2.0);
  EXPECT_DOUBLE_EQ(c.points_mm(2, 0), 40.0);
}

TEST(PointCloud, PlyBinaryLittleEndian) {
  std::string ply =
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\n"
      "property uchar alpha\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n";
  for (int i = 0; i < 3; ++i) {
    for (int k = 0; k < 3; ++k) {
      const double v = 10.0 * i + k;
      ply.append(reinterpret_cast<const char*>(&v), sizeof v);
    }
    ply.push_back('\x7f');
  }
  ply.push_back('\x03');
  for (std::uint32_t i = 0; i < 3; ++i) ply.append(reinterpret_cast<const char*>(&i), sizeof i);
  const PointCloud c = parse_point_cloud(ply, "b.ply", "ply");
  ASSERT_EQ(c.size(), 3);
  EXPECT_DOUBLE_EQ(c.points_mm(1, 2), 21.0);
  // truncated: the vertex block does not fit
  EXPECT_NE(error_of(ply.substr(0, ply.size() - 40), "ply").find("byte offset"), std::string::npos);
  // a lying count is refused before allocating
  std::string huge = ply;
  huge.replace(huge.find("vertex 3"), 8, "vertex 9999999");
  EXPECT_NE(error_of(huge, "ply").find("only"), std::string::npos);
}

TEST(PointCloud, SurfacesGiveVerticesAndNormals) {
  const std::string obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  const PointCloud c = parse_point_cloud(obj, "s.obj", "obj");
  ASSERT_EQ(c.size(), 3);
  ASSERT_TRUE(c.has_normals());
  EXPECT_NEAR(c.normals(2, 0), 1.0, 1e-12);
}

// Found by the fuzzer: the surface parsers do not validate face indices.
TEST(PointCloud, SurfaceWithBadFaceIndexIsRefused) {
  EXPECT_NE(error_of("v 0 0 0\nv 1 0 0\nf 1 2 3\n", "obj").find("uses vertex"), std::string::npos);
}

TEST(PointCloud, BundledMeshesReadAsClouds) {
  const char* d = std::getenv("ARNAV_DATA_DIR");
  ASSERT_NE(d, nullptr);
  const PointCloud ply = read_point_cloud(std::string(d) + "/meshes/sksurgery_liver.ply");
  EXPECT_GT(ply.size(), 1000);
  const PointCloud vtk = read_point_cloud(std::string(d) + "/meshes/liver.vtk");
  EXPECT_GT(vtk.size(), 1000);
  EXPECT_GT(bounding_extent_mm(vtk.points_mm), 100.0);
}

TEST(PointCloud, MetresAreDetected) {
  PointCloud c;
  c.source = "m.xyz";
  c.points_mm = Eigen::Matrix3Xd::Random(3, 50) * 0.05;  // 10 cm patch written in metres
  try {
    check_cloud_units(c, 200.0);
    FAIL() << "metres not detected";
  } catch (const LoadError& e) {
    EXPECT_NE(std::string(e.what()).find("metres"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("m.xyz"), std::string::npos);
  }
  c.points_mm *= 1000.0;
  EXPECT_NO_THROW(check_cloud_units(c, 200.0));
}

TEST(PointCloud, LcmMessage) {
  arnav::point_cloud_t m;
  m.frame_name = "Ref";
  m.source = "pointer";
  m.sequence = 7;
  m.num_points = 2;
  m.p_mm = {{1, 2, 3}, {4, 5, 6}};
  m.num_normals = 2;
  m.normals = {{0, 0, 2}, {0, 1, 0}};
  m.num_ids = 2;
  m.ids = {10, 11};
  std::vector<std::uint8_t> buf(static_cast<std::size_t>(m.getEncodedSize()));
  ASSERT_GT(m.encode(buf.data(), 0, static_cast<int>(buf.size())), 0);
  const PointCloud c = decode_point_cloud_message(buf.data(), buf.size(), "ARNAV_CLOUD_pointer");
  ASSERT_EQ(c.size(), 2);
  EXPECT_DOUBLE_EQ(c.points_mm(2, 1), 6.0);
  EXPECT_DOUBLE_EQ(c.normals(2, 0), 1.0);
  EXPECT_EQ(c.ids, (std::vector<long long>{10, 11}));
  // bad: ids for only one point, non-finite point, truncated bytes
  m.num_ids = 1;
  m.ids = {10};
  buf.resize(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(buf.data(), 0, static_cast<int>(buf.size()));
  try {
    decode_point_cloud_message(buf.data(), buf.size(), "ARNAV_CLOUD_pointer");
    FAIL();
  } catch (const LoadError& e) {
    EXPECT_NE(std::string(e.what()).find("ARNAV_CLOUD_pointer message 7: num_ids 1"), std::string::npos) << e.what();
  }
  m.num_ids = 0;
  m.ids.clear();
  m.p_mm[1][0] = std::nan("");
  buf.resize(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(buf.data(), 0, static_cast<int>(buf.size()));
  EXPECT_THROW(decode_point_cloud_message(buf.data(), buf.size(), "c"), LoadError);
  EXPECT_THROW(decode_point_cloud_message(buf.data(), buf.size() / 2, "c"), LoadError);
  // Found by the fuzzer: counts and string lengths the bytes cannot hold are refused
  // before the generated decoder allocates or throws std::length_error.
  m.p_mm[1][0] = 4.0;
  buf.resize(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(buf.data(), 0, static_cast<int>(buf.size()));
  std::vector<std::uint8_t> huge = buf;
  const std::size_t num_points_at = 8 + 4 + 4 + 4 + 8 + 32;  // fingerprint, "Ref", "pointer", time stamps
  huge[num_points_at] = 0x7f;
  huge[num_points_at + 1] = huge[num_points_at + 2] = huge[num_points_at + 3] = 0xff;
  try {
    decode_point_cloud_message(huge.data(), huge.size(), "c");
    FAIL();
  } catch (const LoadError& e) {
    EXPECT_NE(std::string(e.what()).find("num_points 2147483647 exceeds"), std::string::npos) << e.what();
  }
  std::vector<std::uint8_t> empty_string = buf;
  empty_string[8] = empty_string[9] = empty_string[10] = empty_string[11] = 0;
  EXPECT_THROW(decode_point_cloud_message(empty_string.data(), empty_string.size(), "c"), LoadError);
}
