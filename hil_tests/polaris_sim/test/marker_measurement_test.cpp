// The simulated Polaris' measurement model (marker_measurement.hpp): the pose fitted to
// noisy markers, its noise statistics, dropouts, ROM marker geometry, the scenario block.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>

#include "hil_tests/polaris_sim/marker_measurement.hpp"
#include "hil_tests/polaris_sim/scenario.hpp"

namespace arnav::hil {
namespace {

std::string rom_dir() { return std::string(std::getenv("ARNAV_DATA_DIR")) + "/ndi_roms/"; }

Eigen::Isometry3d some_pose() {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
  X.translation() = Eigen::Vector3d(-120, 85, -1450);
  return X;
}

TEST(MarkerFit, RecoversAnAnalyticPoseExactly) {
  const auto markers = *rom_marker_positions(read_rom(rom_dir() + "8700340.rom"));
  const Eigen::Isometry3d X = some_pose();
  std::vector<Eigen::Vector3d> measured;
  for (const auto& m : markers) measured.push_back(X * m);
  const MarkerFit fit = fit_tool_pose(markers, measured);
  EXPECT_LT((fit.X_NdiTool.matrix() - X.matrix()).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT(fit.rms_error_mm, 1e-9);
}

TEST(MarkerFit, ResidualOfAKnownDistortion) {
  // Markers of a square (side 2a, z = 0) measured as a square scaled by (1 + e): the best
  // rigid fit is the true pose (by symmetry) and every residual is e * a * sqrt(2).
  const double a = 40.0, e = 0.01;
  const std::vector<Eigen::Vector3d> square{{a, a, 0}, {-a, a, 0}, {-a, -a, 0}, {a, -a, 0}};
  const Eigen::Isometry3d X = some_pose();
  std::vector<Eigen::Vector3d> measured;
  for (const auto& m : square) measured.push_back(X * ((1 + e) * m));
  const MarkerFit fit = fit_tool_pose(square, measured);
  EXPECT_LT((fit.X_NdiTool.matrix() - X.matrix()).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_NEAR(fit.rms_error_mm, e * a * std::sqrt(2.0), 1e-9);
}

TEST(MarkerFit, RefusesCollinearOrMismatchedMarkers) {
  const std::vector<Eigen::Vector3d> line{{0, 0, 0}, {0, 0, 50}, {0, 0, 105}};
  EXPECT_THROW(fit_tool_pose(line, line), std::invalid_argument);
  const auto square = default_marker_geometry();
  EXPECT_THROW(fit_tool_pose(square, {square[0], square[1], square[2]}), std::invalid_argument);
}

TEST(MarkerFit, RomMarkerGeometry) {
  const auto m = rom_marker_positions(read_rom(rom_dir() + "8700340.rom"));
  ASSERT_TRUE(m.has_value());
  ASSERT_EQ(m->size(), 4u);
  EXPECT_TRUE((*m)[2].isApprox(Eigen::Vector3d(0, 25, 100)));
  EXPECT_TRUE((*m)[3].isApprox(Eigen::Vector3d(0, -25, 135)));
  // 8700248 holds three collinear markers: no orientation, so no usable geometry.
  EXPECT_FALSE(rom_marker_positions(read_rom(rom_dir() + "8700248.rom")).has_value());
  EXPECT_FALSE(rom_marker_positions(std::vector<std::uint8_t>(100, 0)).has_value());
}

// The realistic model's noise statistics over many frames. The fitted pose at the markers'
// centroid is off by exactly the mean of the marker noise vectors, whose 3-D RMS is
// RMS / sqrt(N); the fit's residual has RMS^2 (3N - 6) / (3N) in expectation. With zero
// noise both are 0, so neither check can pass without the noise.
TEST(MarkerNoise, StatisticsMatchTheConfiguredRms) {
  MeasurementModel model = MeasurementModel::realistic(7);
  model.dropout_rate = 0.0;
  const auto markers = *rom_marker_positions(read_rom(rom_dir() + "8700339.rom"));
  const double n = static_cast<double>(markers.size());
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& m : markers) c += m / n;
  const Eigen::Isometry3d X = some_pose();
  const int frames = 6000;
  double centroid_sq = 0.0, residual_sq = 0.0;
  for (int f = 0; f < frames; ++f) {
    const auto fit = measure_tool(model, X, markers, 1, static_cast<std::uint32_t>(f), 0.12);
    ASSERT_TRUE(fit.has_value());
    centroid_sq += (fit->X_NdiTool * c - X * c).squaredNorm();
    residual_sq += fit->rms_error_mm * fit->rms_error_mm;
  }
  const double centroid_rms = std::sqrt(centroid_sq / frames), residual_rms = std::sqrt(residual_sq / frames);
  EXPECT_NEAR(centroid_rms, 0.25 / std::sqrt(n), 0.05 * 0.25 / std::sqrt(n));
  EXPECT_NEAR(residual_rms, 0.25 * std::sqrt((3 * n - 6) / (3 * n)), 0.05 * 0.25);
  // Twice the noise, twice the error.
  model.marker_noise_rms_mm = 0.5;
  double sq = 0.0;
  for (int f = 0; f < frames; ++f) sq += (measure_tool(model, X, markers, 1, static_cast<std::uint32_t>(f), 0.12)->X_NdiTool * c - X * c).squaredNorm();
  EXPECT_NEAR(std::sqrt(sq / frames), 0.5 / std::sqrt(n), 0.05 * 0.5 / std::sqrt(n));
}

TEST(MarkerNoise, RepeatableFromTheSeedAndFrame) {
  const MeasurementModel a = MeasurementModel::realistic(3);
  const auto markers = default_marker_geometry();
  const auto m1 = measure_tool(a, some_pose(), markers, 2, 1234, 0.12);
  const auto m2 = measure_tool(a, some_pose(), markers, 2, 1234, 0.12);
  ASSERT_TRUE(m1 && m2);
  EXPECT_TRUE(m1->X_NdiTool.isApprox(m2->X_NdiTool, 0.0));
  const auto other_frame = measure_tool(a, some_pose(), markers, 2, 1235, 0.12);
  const auto other_seed = measure_tool(MeasurementModel::realistic(4), some_pose(), markers, 2, 1234, 0.12);
  EXPECT_FALSE(m1->X_NdiTool.translation().isApprox(other_frame->X_NdiTool.translation(), 1e-12));
  EXPECT_FALSE(m1->X_NdiTool.translation().isApprox(other_seed->X_NdiTool.translation(), 1e-12));
  // Ideal: the true pose and the scenario's RMS field.
  const auto ideal = measure_tool(MeasurementModel{}, some_pose(), markers, 2, 1234, 0.12);
  EXPECT_TRUE(ideal->X_NdiTool.isApprox(some_pose(), 0.0));
  EXPECT_EQ(ideal->rms_error_mm, 0.12);
}

TEST(MarkerNoise, DropoutRate) {
  MeasurementModel model = MeasurementModel::realistic(11);
  model.dropout_rate = 0.05;
  const int frames = 20000;
  int dropped = 0;
  for (int f = 0; f < frames; ++f)
    dropped += measure_tool(model, some_pose(), default_marker_geometry(), 0, static_cast<std::uint32_t>(f), 0.12) ? 0 : 1;
  // Binomial: sd = sqrt(20000 * 0.05 * 0.95) = 31; 5 sd.
  EXPECT_NEAR(dropped, 1000, 155);
}

TEST(MarkerNoise, ScenarioBlockAndCommandLine) {
  const std::string dir = ::testing::TempDir();
  const std::string yaml =
      "measurement: {model: realistic, marker_noise_rms_mm: 0.3, dropout_rate: 0.01, seed: 5}\n"
      "tools:\n  - name: pointer\n    rom: " + rom_dir() + "8700340.rom\n"
      "  - name: other\n    markers_mm: [[0, 0, 0], [0, 40, 0], [30, 80, 0]]\n";
  Scenario s = parse_scenario(yaml, "s.yaml", dir);
  EXPECT_FALSE(s.measurement.ideal);
  EXPECT_EQ(s.measurement.marker_noise_rms_mm, 0.3);
  EXPECT_EQ(s.measurement.dropout_rate, 0.01);
  EXPECT_EQ(s.measurement.seed, 5u);
  EXPECT_EQ(s.tools[0].markers_Tool_mm.size(), 4u);  // from the ROM
  EXPECT_TRUE(s.tools[0].markers_Tool_mm[1].isApprox(Eigen::Vector3d(0, 0, 50)));
  EXPECT_EQ(s.tools[1].markers_Tool_mm.size(), 3u);
  set_sensors(s, "realistic", 9);  // keeps the block's values, replaces the seed
  EXPECT_EQ(s.measurement.marker_noise_rms_mm, 0.3);
  EXPECT_EQ(s.measurement.seed, 9u);
  set_sensors(s, "ideal", std::nullopt);
  EXPECT_TRUE(s.measurement.ideal);
  set_sensors(s, "realistic", std::nullopt);
  EXPECT_FALSE(s.measurement.ideal);
  EXPECT_EQ(s.measurement.marker_noise_rms_mm, 0.25);  // the realistic defaults
  EXPECT_TRUE(parse_scenario("tools: []\n", "s.yaml", dir).measurement.ideal);  // no block: ideal
  const auto err = [&](const std::string& text) {
    try {
      parse_scenario(text, "s.yaml", dir);
    } catch (const ScenarioError& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_NE(err("measurement: {model: perfect}\n").find("s.yaml: measurement.model: 'perfect'"), std::string::npos);
  EXPECT_NE(err("measurement: {dropout_rate: 0.9}\n").find("measurement.dropout_rate"), std::string::npos);
  EXPECT_NE(err("measurement: {noise: 1}\n").find("unknown key 'noise'"), std::string::npos);
  EXPECT_NE(err("tools:\n  - name: a\n    markers_mm: [[0, 0, 0], [0, 0, 50], [0, 0, 90]]\n").find("tools[0].markers_mm: needs >= 3"),
            std::string::npos);
  EXPECT_THROW(set_sensors(s, "perfect", std::nullopt), ScenarioError);
}

}  // namespace
}  // namespace arnav::hil
