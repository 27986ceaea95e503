// Scalpel path CSV: interpolation and file:line errors.
#include <gtest/gtest.h>

#include "host/cut/scalpel_path.hpp"
#include "host/mesh/load_error.hpp"

using namespace arnav::host;
using namespace arnav::host::cut;

TEST(ScalpelPath, ParsesAndInterpolates) {
  const ScalpelPath p = parse_scalpel_csv(
      "# planned cut\nt_s,tip_x,tip_y,tip_z,heel_x,heel_y,heel_z,cutting\n0,0,0,0,0,0,10,0\n1.0,10,0,0,10,0,10,1\n2,10,20,0,10,20,10,1\n",
      "p.csv");
  ASSERT_EQ(p.samples.size(), 3u);
  const ScalpelSample s = p.at(0.25);
  EXPECT_NEAR((s.blade.tip_World_mm - Eigen::Vector3d(2.5, 0, 0)).norm(), 0, 1e-12);
  EXPECT_FALSE(s.cutting);  // the earlier sample's flag
  EXPECT_TRUE(p.at(1.5).cutting);
  EXPECT_NEAR((p.at(1.5).blade.heel_World_mm - Eigen::Vector3d(10, 10, 10)).norm(), 0, 1e-12);
  EXPECT_NEAR((p.at(-1).blade.tip_World_mm - Eigen::Vector3d(0, 0, 0)).norm(), 0, 1e-12);
  EXPECT_NEAR((p.at(9).blade.tip_World_mm - Eigen::Vector3d(10, 20, 0)).norm(), 0, 1e-12);
  // Without the cutting column every sample cuts; CRLF line ends are fine.
  const ScalpelPath q = parse_scalpel_csv("t_s,tip_x,tip_y,tip_z,heel_x,heel_y,heel_z\r\n0,1,2,3,4,5,6\r\n", "q.csv");
  EXPECT_TRUE(q.at(0).cutting);
}

TEST(ScalpelPath, BadFilesNameTheLineAndTheFix) {
  const std::string header = "t_s,tip_x,tip_y,tip_z,heel_x,heel_y,heel_z,cutting\n";
  const struct {
    std::string text, expect;
  } cases[] = {
      {"", "p.csv: the file is empty"},
      {"time,x,y\n", "p.csv:1: the header is 'time,x,y'"},
      {header, "p.csv:1: the path has no samples"},
      {header + "0,0,0,0,0,0,10,1\n0.1,0,0,0,0,10\n", "p.csv:3: expected 8 comma-separated values, found 6"},
      {header + "0,0,0,abc,0,0,10,1\n", "p.csv:2: tip_z is 'abc', not a number"},
      {header + "0,0,0,0,0,0,nan,1\n", "p.csv:2: heel_z is not finite"},
      {header + "0,0,0,0,0,0,10,2\n", "p.csv:2: cutting is '2'"},
      {header + "0,0,0,0,0,0,10,1\n0,1,0,0,1,0,10,1\n", "p.csv:3: t_s = 0 does not increase"},
      {header + "0,1,1,1,1,1,1,1\n", "p.csv:2: tip and heel are the same point"},
  };
  for (const auto& c : cases) {
    try {
      parse_scalpel_csv(c.text, "p.csv");
      ADD_FAILURE() << "accepted: " << c.text;
    } catch (const LoadError& e) {
      EXPECT_NE(std::string(e.what()).find(c.expect), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("Fix:"), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(load_scalpel_csv("/nonexistent/path.csv"), LoadError);
}
