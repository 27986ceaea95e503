// AR accuracy evaluation: statistics per view angle, the measurement file parser, and
// the end-to-end chain simulation (noise-free must be exact: it checks every frame
// composition of the chain; with bench noise the error must stay in a plausible range).
#include <cmath>

#include <gtest/gtest.h>

#include "calibration/lib/ar_accuracy.hpp"
#include "calibration/vision/ar_chain_sim.hpp"
#include "calibration/lib/calib_error.hpp"

using namespace arnav::calib;

TEST(ArAccuracy, StatisticsPerViewAngle) {
  std::vector<ArTrial> trials;
  for (double e : {1.0, 2.0, 3.0}) trials.push_back({0.0, e, -1, -1});
  for (double e : {4.0, 4.0}) trials.push_back({30.0, e, -1, -1});
  const auto s = summarize_ar_trials(trials);
  ASSERT_EQ(s.size(), 3u);
  EXPECT_DOUBLE_EQ(s[0].view_angle_deg, 0.0);
  EXPECT_DOUBLE_EQ(s[0].mean_mm, 2.0);
  EXPECT_DOUBLE_EQ(s[0].sd_mm, 1.0);
  EXPECT_DOUBLE_EQ(s[1].mean_mm, 4.0);
  EXPECT_DOUBLE_EQ(s[1].sd_mm, 0.0);
  EXPECT_TRUE(std::isnan(s[2].view_angle_deg));
  EXPECT_EQ(s[2].n, 5);
  EXPECT_DOUBLE_EQ(s[2].mean_mm, 2.8);
  EXPECT_DOUBLE_EQ(s[2].max_mm, 4.0);
}

TEST(ArAccuracy, MeasurementFileParsesAndRejectsBadLines) {
  const auto t = parse_ar_measurements(
      "view_angle_deg,xv,yv,zv,xr,yr,zr\n# angle 1\n0, 10,20,30, 11,20,30\n45;1;1;1;1;4;5\n", "ar.csv");
  ASSERT_EQ(t.size(), 2u);
  EXPECT_DOUBLE_EQ(t[0].error_mm, 1.0);
  EXPECT_DOUBLE_EQ(t[1].error_mm, 5.0);
  EXPECT_DOUBLE_EQ(t[1].view_angle_deg, 45.0);
  try {
    parse_ar_measurements("0,1,2,3,4,5,6\n0,1,2,3,4,5\n", "ar.csv");
    FAIL();
  } catch (const CalibError& e) {
    EXPECT_NE(std::string(e.what()).find("ar.csv:2: expected 7 columns"), std::string::npos) << e.what();
  }
  EXPECT_THROW(parse_ar_measurements("0,1,2,3,4,5,zz\n", "ar.csv"), CalibError);
  EXPECT_THROW(parse_ar_measurements("# nothing\n", "ar.csv"), CalibError);
}

TEST(ArChainSim, NoiseFreeChainIsExact) {
  ArSimOptions o;
  o.ndi_rms_mm = 0.0;
  o.corner_noise_px = 0.0;
  o.runs = 1;
  o.trials_per_angle = 3;
  o.intrinsics_views = 10;
  o.pivot_poses = 30;
  o.hand_eye_poses = 10;
  for (const char* chain : {"marker", "direct"}) {
    o.chain = chain;
    const ArSimResult r = simulate_ar_accuracy(o);
    ASSERT_EQ(r.trials.size(), 12u);
    for (const auto& t : r.trials) {
      EXPECT_LT(t.error_mm, 1e-3) << chain;
      EXPECT_LT(t.image_error_px, 1e-3) << chain;
    }
    EXPECT_LT(r.runs[0].X_CamNdi_error_mm, 1e-3);
    EXPECT_LT(r.runs[0].tip_error_mm, 1e-6);
  }
}

TEST(ArChainSim, BenchNoiseGivesSubMillimetreErrors) {
  ArSimOptions o;  // NDI 0.25 mm RMS, corners 0.2 px
  o.runs = 2;
  o.trials_per_angle = 5;
  const ArSimResult r = simulate_ar_accuracy(o);
  ASSERT_EQ(r.stats.size(), 5u);  // 4 angles + all
  const auto& all = r.stats.back();
  EXPECT_GT(all.mean_mm, 0.05);  // noise must show
  EXPECT_LT(all.mean_mm, 2.0);
  for (const auto& run : r.runs) {
    EXPECT_LT(run.intrinsics_rms_px, 0.3);
    EXPECT_GT(run.pivot_rms_mm, 0.05);
    EXPECT_LT(run.tip_error_mm, 1.0);
  }
}

TEST(ArChainSim, RenderedViewsWithTheDetector) {
  // Every view rendered by the synthetic camera and detected: the chain still works and
  // the detector's corner error is measured (a fraction of a pixel on clean renders).
  ArSimOptions o;
  o.render = true;
  o.runs = 1;
  o.trials_per_angle = 1;
  o.view_angles_deg = {0.0, 40.0};
  o.intrinsics_views = 8;
  o.pivot_poses = 30;
  o.hand_eye_poses = 8;
  const ArSimResult r = simulate_ar_accuracy(o);
  EXPECT_GE(r.views_rendered, 18);
  EXPECT_GT(r.corner_error_rms_px, 0.0);
  EXPECT_LT(r.corner_error_rms_px, 0.5);
  EXPECT_LT(r.stats.back().mean_mm, 3.0);
}
