// Paired-point registration: exact recovery, FRE and Fitzpatrick's TRE prediction
// checked by Monte Carlo, the reflection guard and degenerate configurations.
#include <gtest/gtest.h>

#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/point_registration.hpp"
#include "calibration/lib/test/test_util.hpp"

using namespace arnav::calib;
using arnav::calib::test::gaussian3;

namespace {

std::vector<Eigen::Vector3d> fiducials_model() {
  return {{0, 0, 0}, {100, 0, 10}, {0, 80, -5}, {90, 70, 30}, {40, 20, 60}, {-30, 50, 20}};
}

Eigen::Isometry3d truth() {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = Eigen::AngleAxisd(0.8, Eigen::Vector3d(0.2, -1, 0.5).normalized()).toRotationMatrix();
  X.translation() = Eigen::Vector3d(-300, 120, -900);
  return X;
}

}  // namespace

TEST(PointRegistration, NoiseFreeIsExact) {
  const auto p_Model = fiducials_model();
  std::vector<Eigen::Vector3d> p_Ref;
  for (const auto& p : p_Model) p_Ref.push_back(truth() * p);
  const auto r = register_paired_points(p_Ref, p_Model);
  EXPECT_LT((r.X_AB.matrix() - truth().matrix()).norm(), 1e-9);
  EXPECT_LT(r.fre_rms_mm, 1e-9);
  EXPECT_FALSE(r.reflection_guarded);
}

TEST(PointRegistration, FitzpatrickTrePredictionMatchesMonteCarlo) {
  const auto p_Model = fiducials_model();
  const Eigen::Vector3d target_Model(50, 200, 40);  // outside the fiducial cloud
  const double fle = 0.5;                            // RMS 3D, per-axis fle/sqrt(3)
  std::mt19937 rng(7);
  double sum_tre2 = 0.0;
  double sum_fre2 = 0.0;
  double predicted = 0.0;
  const int trials = 3000;
  for (int k = 0; k < trials; ++k) {
    std::vector<Eigen::Vector3d> p_Ref;
    for (const auto& p : p_Model) p_Ref.push_back(truth() * p + gaussian3(rng, fle / std::sqrt(3.0)));
    const auto r = register_paired_points(p_Ref, p_Model);
    sum_tre2 += (r.X_AB * target_Model - truth() * target_Model).squaredNorm();
    sum_fre2 += r.fre_rms_mm * r.fre_rms_mm;
    if (k == 0) predicted = predicted_tre_mm(r, truth() * target_Model, fle, 6);
  }
  const double tre_mc = std::sqrt(sum_tre2 / trials);
  // Fitzpatrick: <FRE^2> = (1 - 2/N) FLE^2.
  EXPECT_NEAR(std::sqrt(sum_fre2 / trials), fle * std::sqrt(1.0 - 2.0 / 6.0), 0.02);
  EXPECT_NEAR(predicted, tre_mc, 0.08 * tre_mc) << "predicted " << predicted << " MC " << tre_mc;
}

TEST(PointRegistration, FleEstimatedFromFre) {
  const auto p_Model = fiducials_model();
  std::mt19937 rng(9);
  std::vector<Eigen::Vector3d> p_Ref;
  for (const auto& p : p_Model) p_Ref.push_back(truth() * p + gaussian3(rng, 0.3));
  const auto r = register_paired_points(p_Ref, p_Model);
  EXPECT_NEAR(r.fle_rms_mm, r.fre_rms_mm * std::sqrt(6.0 / 4.0), 1e-12);
  EXPECT_GT(predicted_tre_mm(r, truth() * Eigen::Vector3d(500, 500, 500)),
            predicted_tre_mm(r, r.centroid_A));
}

TEST(PointRegistration, ReflectionGuardKeepsARotation) {
  // Mirrored correspondences (z negated): the best orthogonal fit is a reflection.
  const auto p_Model = fiducials_model();
  std::vector<Eigen::Vector3d> p_Ref;
  for (const auto& p : p_Model) p_Ref.push_back(Eigen::Vector3d(p.x(), p.y(), -p.z()));
  const auto r = register_paired_points(p_Ref, p_Model);
  EXPECT_TRUE(r.reflection_guarded);
  EXPECT_NEAR(r.X_AB.linear().determinant(), 1.0, 1e-9);
  EXPECT_GT(r.fre_rms_mm, 1.0);  // a mirror cannot be fitted by a rotation
}

TEST(PointRegistration, RejectsDegenerateInput) {
  EXPECT_THROW(register_paired_points({{0, 0, 0}, {1, 0, 0}}, {{0, 0, 0}, {1, 0, 0}}), DegenerateInput);
  const std::vector<Eigen::Vector3d> line = {{0, 0, 0}, {10, 0, 0}, {20, 0, 0}, {30, 0, 0}};
  try {
    register_paired_points(line, line);
    FAIL();
  } catch (const DegenerateInput& e) {
    EXPECT_NE(std::string(e.what()).find("collinear"), std::string::npos);
  }
  EXPECT_THROW(register_paired_points(line, {{0, 0, 0}}), CalibError);
}
