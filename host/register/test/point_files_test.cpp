// Landmark and target CSV files: header, names, counts, numbers, with file:line errors.
#include <gtest/gtest.h>

#include "host/register/point_files.hpp"
#include "host/mesh/load_error.hpp"

using namespace arnav::host;

namespace {
const char* kHeader = "name,model_x,model_y,model_z,intraop_x,intraop_y,intraop_z\n";

std::string landmark_error(const std::string& text) {
  try {
    parse_landmarks(text, "lm.csv");
  } catch (const LoadError& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(PointFiles, Landmarks) {
  const auto l = parse_landmarks(std::string(kHeader) + "# touched\na,0,0,0,1,2,3\nb, 1,0,0,2,2,3\nc,0,1,0,1,3,3\n", "lm.csv");
  ASSERT_EQ(l.size(), 3u);
  EXPECT_EQ(l[1].name, "b");
  EXPECT_DOUBLE_EQ(l[2].p_Intraop_mm.y(), 3.0);
  EXPECT_EQ(l[0].line, 3);
}

TEST(PointFiles, LandmarkErrors) {
  EXPECT_NE(landmark_error(std::string(kHeader) + "a,0,0,0,1,2,3\nb,1,0,0,2,2,3\n").find("at least 3"), std::string::npos);
  EXPECT_NE(landmark_error(std::string(kHeader) + "a,0,0,0,1,2,3\na,1,0,0,2,2,3\nc,0,1,0,1,3,3\n").find("lm.csv:3: landmark name 'a' appears twice"),
            std::string::npos);
  EXPECT_NE(landmark_error(std::string(kHeader) + "a,0,0,nan,1,2,3\n").find("lm.csv:2:"), std::string::npos);
  EXPECT_NE(landmark_error(std::string(kHeader) + "a,0,0,1,2,3\n").find("lm.csv:2: expected 7"), std::string::npos);
  EXPECT_NE(landmark_error("name,x,y,z\n").find("lm.csv:1: expected the header"), std::string::npos);
  EXPECT_NE(landmark_error("").find("empty"), std::string::npos);
}

TEST(PointFiles, TargetsRoundTrip) {
  const auto t = parse_targets("name,x_mm,y_mm,z_mm\ntumour_centre,70,160,140\nportal,1.5,-2,3e1\n", "t.csv");
  ASSERT_EQ(t.size(), 2u);
  EXPECT_DOUBLE_EQ(t[1].p_mm.z(), 30.0);
  const std::string dir = ::testing::TempDir();
  write_targets(dir + "/t_out.csv", t);
  const auto back = read_targets(dir + "/t_out.csv");
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back[0].name, "tumour_centre");
  EXPECT_NEAR(back[1].p_mm.x(), 1.5, 1e-12);
  EXPECT_THROW(parse_targets("name,x_mm,y_mm,z_mm\na,1,2,3\na,1,2,3\n", "t.csv"), LoadError);
}
