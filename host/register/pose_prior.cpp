#include "host/register/pose_prior.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <stdexcept>

namespace arnav::host {
namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;
constexpr double kRotationScaleMm = 100.0;  // 1 rad counts as 100 mm of motion when directions are compared

Eigen::Matrix3d skew(const Eigen::Vector3d& a) {
  Eigen::Matrix3d s;
  s << 0, -a.z(), a.y(), a.z(), 0, -a.x(), -a.y(), a.x(), 0;  // s * b = a x b
  return s;
}

std::string vec_text(const Eigen::Vector3d& v) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "(%.2f, %.2f, %.2f)", v.x(), v.y(), v.z());
  return buf;
}

Matrix6d symmetric_inverse(const Matrix6d& M) {
  Eigen::SelfAdjointEigenSolver<Matrix6d> es(0.5 * (M + M.transpose()));
  const double mx = std::max(es.eigenvalues().cwiseAbs().maxCoeff(), 1e-300);
  Vector6d inv;
  for (int i = 0; i < 6; ++i) inv[i] = es.eigenvalues()[i] > 1e-12 * mx ? 1.0 / es.eigenvalues()[i] : 0.0;
  return es.eigenvectors() * inv.asDiagonal() * es.eigenvectors().transpose();
}

}  // namespace

Matrix6d PosePrior::information() const { return symmetric_inverse(covariance); }

PosePrior isotropic_pose_prior(const Eigen::Isometry3d& X, const Eigen::Vector3d& centre, double rotation_deg, double translation_mm,
                               const std::string& source) {
  if (!(rotation_deg > 0) || !(translation_mm > 0) || !std::isfinite(rotation_deg) || !std::isfinite(translation_mm))
    throw std::invalid_argument("pose prior: the uncertainty must be positive (rotation " + std::to_string(rotation_deg) + " deg, translation " +
                                std::to_string(translation_mm) + " mm)");
  PosePrior p;
  p.X_IntraopModel = X;
  p.centre_Model_mm = centre;
  p.source = source;
  p.covariance.setZero();
  const double r = rotation_deg / kDeg;
  p.covariance.topLeftCorner<3, 3>() = r * r * Eigen::Matrix3d::Identity();
  p.covariance.bottomRightCorner<3, 3>() = translation_mm * translation_mm * Eigen::Matrix3d::Identity();
  return p;
}

PosePrior landmark_pose_prior(const std::vector<Landmark>& landmarks, const Eigen::Isometry3d& X, double fre_rms_mm, const Eigen::Vector3d& centre,
                              double landmark_error_mm) {
  const int n = static_cast<int>(landmarks.size());
  if (n < 3) throw std::invalid_argument("pose prior: the landmark fit needs at least 3 landmarks, got " + std::to_string(n));
  if (!(landmark_error_mm > 0)) throw std::invalid_argument("pose prior: the landmark error must be positive");
  // Fitzpatrick: E[FRE^2] = (1 - 2/N) FLE^2; the error given is a floor (three landmarks
  // say little about their own error).
  const double fle_from_fre = n > 2 ? fre_rms_mm * std::sqrt(static_cast<double>(n) / (n - 2.0)) : 0.0;
  const double fle = std::max(landmark_error_mm, fle_from_fre);
  const double s2 = fle * fle / 3.0;
  Matrix6d H = Matrix6d::Zero();
  for (const Landmark& l : landmarks) {
    Eigen::Matrix<double, 3, 6> J;
    J.leftCols<3>() = -skew(l.p_Model_mm - centre);
    J.rightCols<3>().setIdentity();
    H += J.transpose() * J;
  }
  PosePrior p;
  p.X_IntraopModel = X;
  p.centre_Model_mm = centre;
  p.source = "landmarks";
  p.covariance = s2 * symmetric_inverse(H);
  return p;
}

Vector6d pose_deviation(const PosePrior& prior, const Eigen::Isometry3d& T) {
  const Eigen::Isometry3d delta = T * prior.X_IntraopModel;  // T * T0^-1, T0 = X0^-1
  const Eigen::AngleAxisd aa(delta.rotation());
  Vector6d xi;
  xi.head<3>() = aa.angle() * aa.axis();
  xi.tail<3>() = delta * prior.centre_Model_mm - prior.centre_Model_mm;
  return xi;
}

Matrix6d pose_deviation_jacobian(const PosePrior& prior, const Eigen::Isometry3d& T, const Eigen::Vector3d& lc) {
  const Eigen::Isometry3d delta = T * prior.X_IntraopModel;
  const Eigen::Vector3d a = delta * prior.centre_Model_mm - lc;
  Matrix6d B = Matrix6d::Identity();
  B.bottomLeftCorner<3, 3>() = -skew(a);  // d(omega x a)/d omega
  return B;
}

void add_pose_prior(const PosePrior& prior, const Eigen::Isometry3d& T, const Eigen::Vector3d& lc, double scale2, Eigen::Ref<Eigen::MatrixXd> A6,
                    Eigen::Ref<Eigen::VectorXd> rhs6) {
  const Matrix6d P = prior.information();
  const Matrix6d B = pose_deviation_jacobian(prior, T, lc);
  const Vector6d xi = pose_deviation(prior, T);
  A6 += scale2 * B.transpose() * P * B;
  rhs6 -= scale2 * B.transpose() * P * xi;
}

PosePosterior pose_posterior(const PosePrior* prior, const Eigen::Isometry3d& T, const Eigen::Vector3d& lc, const Matrix6d& H_data, double noise2) {
  PosePosterior post;
  if (!(noise2 > 0) || !H_data.allFinite()) return post;
  // The data's information in the prior's coordinates xi (about the prior's centre, or
  // about lc without a prior): J_xi = J_step B^-1.
  Matrix6d Binv = Matrix6d::Identity();
  if (prior) Binv = pose_deviation_jacobian(*prior, T, lc).inverse();
  const Matrix6d Hd = Binv.transpose() * H_data * Binv / noise2;
  const Matrix6d P = prior ? prior->information() : Matrix6d::Zero();
  const Matrix6d cov = symmetric_inverse(Hd + P);
  for (int i = 0; i < 3; ++i) {
    post.rotation_sigma_deg[i] = std::sqrt(std::max(0.0, cov(i, i))) * kDeg;
    post.translation_sigma_mm[i] = std::sqrt(std::max(0.0, cov(i + 3, i + 3)));
    if (prior) {
      post.prior_rotation_sigma_deg[i] = std::sqrt(std::max(0.0, prior->covariance(i, i))) * kDeg;
      post.prior_translation_sigma_mm[i] = std::sqrt(std::max(0.0, prior->covariance(i + 3, i + 3)));
    }
  }
  // Directions: with a prior, those where the data's information is below the prior's
  // (generalised eigenvalues of Hd against P below 1); without, those where it is below
  // 1e-4 of the best-constrained direction (in rad * 100 mm and mm units).
  Matrix6d W = Matrix6d::Identity();  // whitening: xi = W u
  if (prior) {
    Eigen::SelfAdjointEigenSolver<Matrix6d> ps(0.5 * (prior->covariance + prior->covariance.transpose()));
    W = ps.eigenvectors() * ps.eigenvalues().cwiseMax(0.0).cwiseSqrt().asDiagonal();
  } else {
    W.topLeftCorner<3, 3>() /= kRotationScaleMm;
  }
  const Matrix6d M = W.transpose() * Hd * W;
  Eigen::SelfAdjointEigenSolver<Matrix6d> es(0.5 * (M + M.transpose()));
  const double threshold = prior ? 1.0 : 1e-4 * std::max(es.eigenvalues().maxCoeff(), 1e-300);
  for (int i = 0; i < 6; ++i) {
    if (es.eigenvalues()[i] >= threshold) continue;
    Vector6d v = W * es.eigenvectors().col(i);
    v.head<3>() *= kRotationScaleMm;
    if (!(v.norm() > 0)) continue;
    v.normalize();
    const Eigen::Vector3d r = v.head<3>(), t = v.tail<3>();
    std::string text;
    if (r.norm() >= t.norm()) text = "rotation about " + vec_text(r.normalized()) + (t.norm() > 0.3 ? " with translation along " + vec_text(t.normalized()) : "");
    else text = "translation along " + vec_text(t.normalized()) + (r.norm() > 0.3 ? " with rotation about " + vec_text(r.normalized()) : "");
    post.unconstrained.push_back(v);
    post.unconstrained_text.push_back(text);
  }
  if (prior) {
    post.deviation = pose_deviation(*prior, T);
    post.deviation_sigmas = std::sqrt(std::max(0.0, post.deviation.dot(P * post.deviation)));
  }
  post.valid = true;
  return post;
}

double estimate_point_noise_mm(const Eigen::Matrix3Xd& pts, int k) {
  const int n = static_cast<int>(pts.cols());
  if (n < 20) return 0.0;
  k = std::clamp(k, 6, n - 1);
  const int queries = std::min(n, 1500);
  const int stride = std::max(1, n / queries);
  std::vector<double> res;
  std::vector<std::pair<double, int>> d(static_cast<std::size_t>(n));
  for (int qi = 0; qi < n; qi += stride) {
    for (int j = 0; j < n; ++j) d[static_cast<std::size_t>(j)] = {(pts.col(j) - pts.col(qi)).squaredNorm(), j};
    std::nth_element(d.begin(), d.begin() + k, d.end());  // d[0..k] the k+1 closest (the point itself among them)
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    int m = 0;
    for (int j = 0; j <= k; ++j)
      if (d[static_cast<std::size_t>(j)].second != qi) {
        c += pts.col(d[static_cast<std::size_t>(j)].second);
        ++m;
      }
    c /= m;
    Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
    for (int j = 0; j <= k; ++j)
      if (d[static_cast<std::size_t>(j)].second != qi) {
        const Eigen::Vector3d e = pts.col(d[static_cast<std::size_t>(j)].second) - c;
        C += e * e.transpose();
      }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(C);
    res.push_back(std::abs(es.eigenvectors().col(0).dot(pts.col(qi) - c)));
  }
  const auto mid = res.begin() + static_cast<std::ptrdiff_t>(res.size() / 2);
  std::nth_element(res.begin(), mid, res.end());
  // The point is not in its plane's fit: its residual's variance is about noise^2 (1 + 1/k)
  // plus the plane's tilt error; the neighbours' plane itself absorbed ~3 of k dofs.
  const double sigma = 1.4826 * (*mid);
  return sigma / std::sqrt(1.0 + 1.0 / k + 3.0 / k);
}

}  // namespace arnav::host
