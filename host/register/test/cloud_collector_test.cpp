// Live point clouds: PointCloudCollector accumulates arnav.point_cloud_t messages (drops
// duplicates, counts lost ones, refuses another frame, rejects corrupt bytes naming the
// channel), and arnav-register registers from a swab replayed from an LCM log
// (--lcm file://LOG?speed=0: the same subscriber code as a live udpm URL).
#include <gtest/gtest.h>

#include <lcm/lcm-cpp.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <sys/wait.h>

#include "arnav/point_cloud_t.hpp"
#include "host/register/cloud_collector.hpp"
#include "host/register/synthetic_data.hpp"
#include "host/mesh/load_error.hpp"
#include "host/scene/scene.hpp"

using namespace arnav::host;

namespace {

arnav::point_cloud_t message(const Eigen::Matrix3Xd& p, long long sequence, const std::string& frame, bool normals = false) {
  arnav::point_cloud_t m;
  m.frame_name = frame;
  m.source = "pointer";
  m.sequence = sequence;
  m.capture_time_wall_us = m.publish_time_mono_us = m.publish_time_wall_us = 0;
  m.num_points = static_cast<int>(p.cols());
  for (int i = 0; i < p.cols(); ++i) m.p_mm.push_back({p(0, i), p(1, i), p(2, i)});
  m.num_normals = normals ? m.num_points : 0;
  if (normals)
    for (int i = 0; i < p.cols(); ++i) m.normals.push_back({0.0, 0.0, 1.0});
  m.num_ids = 0;
  return m;
}

std::vector<unsigned char> bytes(const arnav::point_cloud_t& m) {
  std::vector<unsigned char> b(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(b.data(), 0, static_cast<int>(b.size()));
  return b;
}

Eigen::Matrix3Xd points(int n, double offset) {
  Eigen::Matrix3Xd p(3, n);
  for (int i = 0; i < n; ++i) p.col(i) = Eigen::Vector3d(offset + i, 2.0 * i, 3.0);
  return p;
}

}  // namespace

TEST(CloudCollector, AccumulatesDropsDuplicatesCountsGapsRefusesOtherFrames) {
  PointCloudCollector c;
  auto add = [&](const arnav::point_cloud_t& m) {
    const auto b = bytes(m);
    return c.add_message(b.data(), b.size(), "ARNAV_CLOUD_pointer");
  };
  EXPECT_EQ(add(message(points(4, 0), 10, "Ref")), 4);
  EXPECT_EQ(add(message(points(3, 100), 11, "Ref")), 3);
  EXPECT_EQ(add(message(points(3, 100), 11, "Ref")), 0);    // duplicate
  EXPECT_EQ(add(message(points(5, 200), 12, "Ndi")), 0);    // reference tool not seen: another frame
  EXPECT_EQ(add(message(points(2, 300), 14, "Ref")), 2);    // 13 lost
  EXPECT_EQ(c.points(), 9);
  EXPECT_EQ(c.messages(), 3);
  EXPECT_EQ(c.duplicates(), 1);
  EXPECT_EQ(c.wrong_frame(), 1);
  EXPECT_EQ(c.missed(), 1);
  EXPECT_EQ(c.frame_name(), "Ref");
  const PointCloud cloud = c.cloud();
  ASSERT_EQ(cloud.size(), 9);
  EXPECT_EQ(cloud.points_mm.col(4), Eigen::Vector3d(100, 0, 3));
  EXPECT_EQ(cloud.points_mm.col(8), Eigen::Vector3d(301, 2, 3));
  EXPECT_FALSE(cloud.has_normals());
  EXPECT_NE(c.summary().find("1 messages refused in frame 'Ndi'"), std::string::npos) << c.summary();
  EXPECT_NE(c.summary().find("1 messages lost"), std::string::npos) << c.summary();
}

TEST(CloudCollector, ExpectedFrameAndNormalsOnlyWhenAllHaveThem) {
  PointCloudCollector c("Ref");
  auto b1 = bytes(message(points(3, 0), 1, "Ndi"));
  EXPECT_EQ(c.add_message(b1.data(), b1.size(), "CH"), 0);
  auto b2 = bytes(message(points(3, 0), 2, "Ref", true));
  EXPECT_EQ(c.add_message(b2.data(), b2.size(), "CH"), 3);
  EXPECT_TRUE(c.cloud().has_normals());
  auto b3 = bytes(message(points(2, 9), 3, "Ref", false));
  EXPECT_EQ(c.add_message(b3.data(), b3.size(), "CH"), 2);
  EXPECT_FALSE(c.cloud().has_normals());  // mixed: none kept
  EXPECT_EQ(c.cloud().size(), 5);
}

TEST(CloudCollector, CorruptMessageNamesTheChannel) {
  PointCloudCollector c;
  auto b = bytes(message(points(3, 0), 7, "Ref"));
  b.resize(b.size() - 5);  // truncated
  try {
    c.add_message(b.data(), b.size(), "ARNAV_CLOUD_pointer");
    FAIL() << "no error for a truncated message";
  } catch (const LoadError& e) {
    EXPECT_NE(std::string(e.what()).find("ARNAV_CLOUD_pointer"), std::string::npos) << e.what();
  }
  auto nan = message(points(3, 0), 8, "Ref");
  nan.p_mm[1][2] = std::numeric_limits<double>::quiet_NaN();
  const auto bn = bytes(nan);
  EXPECT_THROW(c.add_message(bn.data(), bn.size(), "ARNAV_CLOUD_pointer"), LoadError);
  EXPECT_EQ(c.points(), 0);
}

// arnav-register --lcm: a swab of the coarse liver's front (30 % of the surface, 0.5 mm
// noise, rigidly moved) published as 40-point messages, replayed from an LCM log.
TEST(CloudCollector, ArnavRegisterRegistersAReplayedSwab) {
  const char* bin = std::getenv("ARNAV_BINARY_DIR");
  const char* data = std::getenv("ARNAV_DATA_DIR");
  ASSERT_TRUE(bin && data);
  const std::string scene_path = std::string(data) + "/liver/liver_coarse.scene.yaml";
  const Scene scene = load_scene(scene_path);
  std::mt19937 rng(5);
  const Eigen::Vector3d view(0, -1, 0);
  Eigen::Index front = 0;
  (scene.organ_surface.positions_World_mm.transpose() * view).maxCoeff(&front);
  SampledPatch patch = sample_patch(scene.organ_surface.positions_World_mm, scene.organ_surface.tris,
                                    scene.organ_surface.positions_World_mm.col(front), view, 0.3, 4.0, rng);
  add_noise(patch.points_mm, 0.5, rng);
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();  // a small offset: ICP from the identity
  X.linear() = Eigen::AngleAxisd(0.03, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  X.translation() = Eigen::Vector3d(2, -1, 1.5);
  const Eigen::Matrix3Xd pts = X * patch.points_mm;
  const std::string dir = std::string(bin) + "/test_out/register_live";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string log = dir + "/swab.lcmlog";
  {
    lcm::LogFile f(log, "w");
    ASSERT_TRUE(f.good());
    long long seq = 0;
    for (int i = 0; i < pts.cols(); i += 40) {
      const int n = std::min<int>(40, static_cast<int>(pts.cols()) - i);
      const auto b = bytes(message(pts.middleCols(i, n), seq++, "Ref"));
      lcm::LogEvent e;
      e.eventnum = seq;
      e.timestamp = 1000000 + seq * 20000;
      e.channel = "ARNAV_CLOUD_pointer";
      e.datalen = static_cast<int32_t>(b.size());
      e.data = const_cast<unsigned char*>(b.data());
      ASSERT_EQ(f.writeEvent(&e), 0);
    }
  }
  const std::string reg = std::string(bin) + "/host/register/arnav-register";
  const std::string cmd = "OMP_WAIT_POLICY=PASSIVE '" + reg + "' '" + scene_path + "' --lcm 'file://" + log + "?speed=0' --security off --swab-seconds 5 --rigid-only --out '" +
                          dir + "/out' > '" + dir + "/stdout.txt' 2> '" + dir + "/stderr.txt'";
  const int rc = std::system(cmd.c_str());
  std::ifstream err(dir + "/stderr.txt");
  std::stringstream es;
  es << err.rdbuf();
  ASSERT_EQ(rc, 0) << es.str();
  EXPECT_NE(es.str().find(std::to_string(pts.cols()) + " points from"), std::string::npos) << es.str();
  EXPECT_TRUE(std::filesystem::exists(dir + "/out/swab.xyz"));
  EXPECT_TRUE(std::filesystem::exists(dir + "/out/X_IntraopModel.yaml"));
  // the swab read back as a file registers the same way
  const PointCloud back = read_point_cloud(dir + "/out/swab.xyz");
  EXPECT_EQ(back.size(), pts.cols());

  // nothing on the channel: exit 2 naming the channel
  const std::string cmd2 = "'" + reg + "' '" + scene_path + "' --lcm 'file://" + log + "?speed=0' --security off --cloud-channel ARNAV_CLOUD_stereo --swab-wait-seconds 1 --out '" +
                           dir + "/out2' > /dev/null 2> '" + dir + "/stderr2.txt'";
  const int rc2 = std::system(cmd2.c_str());
  ASSERT_TRUE(WIFEXITED(rc2));
  EXPECT_EQ(WEXITSTATUS(rc2), 2);
  std::ifstream err2(dir + "/stderr2.txt");
  std::stringstream es2;
  es2 << err2.rdbuf();
  EXPECT_NE(es2.str().find("ARNAV_CLOUD_stereo"), std::string::npos) << es2.str();
}
