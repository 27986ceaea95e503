#include "host/register/rigid_registration.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>

#include <Eigen/Dense>

#include "calibration/lib/point_registration.hpp"
#include "host/register/surface_index.hpp"

namespace arnav::host {
namespace {

double median_of(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

Eigen::Isometry3d exp_se3(const Eigen::Matrix<double, 6, 1>& xi) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  const Eigen::Vector3d w = xi.head<3>();
  const double a = w.norm();
  if (a > 1e-15) T.linear() = Eigen::AngleAxisd(a, w / a).toRotationMatrix();
  T.translation() = xi.tail<3>();
  return T;
}

// The robust data term at pose T (data -> Model) over scale^2: Tukey's biweight on the
// distance to the surface (the kernel of the MAP steps with a prior).
double icp_objective(const SurfaceIndex& index, const Eigen::Matrix3Xd& data, const Eigen::Isometry3d& T, const IcpOptions& o, double scale) {
  const int n = static_cast<int>(data.cols());
  std::vector<double> d(static_cast<std::size_t>(n));
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    const SurfaceHit h = index.closest(T * data.col(i), o.max_distance_mm);
    d[static_cast<std::size_t>(i)] = h.tri >= 0 ? h.distance_mm : o.max_distance_mm;
  }
  // Every point counts (a pose that pushes points out of the kept set is not rewarded for
  // it): rho(r) = c^2/6 (1 - (1 - (r/c)^2)^3), c^2/6 beyond c.
  const double c = o.tukey_sigmas * scale;
  double sum = 0.0;
  for (double di : d) {
    const double u = std::min(di / c, 1.0);
    const double v = 1.0 - u * u;
    sum += c * c / 6.0 * (1.0 - v * v * v);
  }
  return 2.0 * sum / (scale * scale);  // 2 rho: r^2 near zero, as the Gauss-Newton data term
}

double prior_term(const PosePrior& prior, const Eigen::Isometry3d& T) {
  const Vector6d xi = pose_deviation(prior, T);
  return xi.dot(prior.information() * xi);
}

}  // namespace

double rotation_angle_deg(const Eigen::Isometry3d& X) {
  return Eigen::AngleAxisd(X.rotation()).angle() * 180.0 / std::numbers::pi;
}

LandmarkFit register_landmarks(const std::vector<Landmark>& landmarks) {
  std::vector<Eigen::Vector3d> a, b;
  for (const auto& l : landmarks) {
    a.push_back(l.p_Intraop_mm);
    b.push_back(l.p_Model_mm);
  }
  LandmarkFit f;
  try {
    f.fit = calib::register_paired_points(a, b);
  } catch (const std::exception& e) {
    throw std::invalid_argument(std::string("landmark registration: ") + e.what());
  }
  f.X_IntraopModel = f.fit.X_AB;
  f.count = static_cast<int>(landmarks.size());
  return f;
}

double LandmarkFit::predicted_tre_mm(const Eigen::Vector3d& p_Model_mm, double fle_rms_mm) const {
  return calib::predicted_tre_mm(fit, X_IntraopModel * p_Model_mm, fle_rms_mm, count);
}

IcpResult icp_point_to_plane(const Eigen::Matrix3Xd& model_positions_mm, const std::vector<std::array<int, 3>>& model_tris,
                             const Eigen::Matrix3Xd& data_Intraop_mm, const Eigen::Matrix3Xd& data_normals_Intraop,
                             const Eigen::Isometry3d& X_IntraopModel_initial, const IcpOptions& o, const PosePrior* prior) {
  const auto t0 = std::chrono::steady_clock::now();
  IcpResult res;
  res.X_IntraopModel = X_IntraopModel_initial;
  const int n = static_cast<int>(data_Intraop_mm.cols());
  res.X_IntraopModel_fit = X_IntraopModel_initial;
  if (n == 0) {
    res.summary.termination = "no data";
    return res;
  }
  const SurfaceIndex index(model_positions_mm, model_tris);
  const bool normals = data_normals_Intraop.cols() == n;
  const double cos_max = std::cos(o.max_normal_angle_deg * std::numbers::pi / 180.0);
  // T maps data (Intraop) into Model.
  Eigen::Isometry3d T = X_IntraopModel_initial.inverse();
  std::vector<SurfaceHit> hit(static_cast<std::size_t>(n));
  std::vector<double> dist(static_cast<std::size_t>(n)), r(static_cast<std::size_t>(n));
  std::vector<char> keep(static_cast<std::size_t>(n));
  const double extent = (data_Intraop_mm.rowwise().maxCoeff() - data_Intraop_mm.rowwise().minCoeff()).norm();
  res.summary.termination = "max_iterations";
  double search_mm = std::numeric_limits<double>::infinity();  // first pass: every point finds the surface
  Matrix6d H_last = Matrix6d::Zero();  // the data term's Gauss-Newton matrix at T_last (for the posterior)
  Eigen::Isometry3d T_last = T;
  Eigen::Vector3d centre_last = Eigen::Vector3d::Zero();
  double sigma_last = 0.0;
  for (int it = 0; it < o.max_iterations; ++it) {
#pragma omp parallel for schedule(static)
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d q = T * data_Intraop_mm.col(i);
      hit[static_cast<std::size_t>(i)] = index.closest(q, search_mm);
      dist[static_cast<std::size_t>(i)] = hit[static_cast<std::size_t>(i)].distance_mm;
      r[static_cast<std::size_t>(i)] =
          hit[static_cast<std::size_t>(i)].tri >= 0 ? hit[static_cast<std::size_t>(i)].normal.dot(q - hit[static_cast<std::size_t>(i)].point) : 0.0;
    }
    // Trimming: the closest keep_fraction, within max_distance (and within 3x the median
    // distance, so a far-off start is not cut to nothing).
    std::vector<double> sorted = dist;
    const auto kth = sorted.begin() + std::clamp(static_cast<std::ptrdiff_t>(std::ceil(o.keep_fraction * n)) - 1, std::ptrdiff_t{0},
                                                 static_cast<std::ptrdiff_t>(n - 1));
    std::nth_element(sorted.begin(), kth, sorted.end());
    const double d_keep = *kth;
    const double d_max = std::max(o.max_distance_mm, 3.0 * median_of(dist));
    search_mm = d_max;  // later passes need not look further than a kept pair could be
    int used = 0;
    for (int i = 0; i < n; ++i) {
      bool k = hit[static_cast<std::size_t>(i)].tri >= 0 && dist[static_cast<std::size_t>(i)] <= d_keep && dist[static_cast<std::size_t>(i)] <= d_max;
      if (k && normals) {
        const Eigen::Vector3d nd = T.linear() * data_normals_Intraop.col(i);
        k = std::abs(nd.dot(hit[static_cast<std::size_t>(i)].normal)) >= cos_max;
      }
      keep[static_cast<std::size_t>(i)] = k;
      used += k ? 1 : 0;
    }
    if (used < 6) {
      res.summary.termination = "too few inliers (" + std::to_string(used) + ")";
      break;
    }
    std::vector<double> abs_r;
    for (int i = 0; i < n; ++i)
      if (keep[static_cast<std::size_t>(i)]) abs_r.push_back(std::abs(r[static_cast<std::size_t>(i)]));
    const double sigma = std::max(o.min_sigma_mm, 1.4826 * median_of(abs_r));
    const double c = o.huber_sigmas * sigma;
    const double c_tukey = o.tukey_sigmas * sigma;
    Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> g = Eigen::Matrix<double, 6, 1>::Zero();
    double ss = 0.0;
    // Linearise about the data centroid in Model so rotation and translation are balanced.
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (int i = 0; i < n; ++i)
      if (keep[static_cast<std::size_t>(i)]) centre += T * data_Intraop_mm.col(i);
    centre /= used;
    for (int i = 0; i < n; ++i) {
      if (!keep[static_cast<std::size_t>(i)]) continue;
      const Eigen::Vector3d q = T * data_Intraop_mm.col(i) - centre;
      const Eigen::Vector3d& nm = hit[static_cast<std::size_t>(i)].normal;
      const double ri = r[static_cast<std::size_t>(i)];
      double w = std::abs(ri) <= c ? 1.0 : c / std::abs(ri);
      if (prior) {
        const double u = std::abs(ri) / c_tukey;
        w = u < 1.0 ? (1.0 - u * u) * (1.0 - u * u) : 0.0;
      }
      Eigen::Matrix<double, 6, 1> J;
      J << q.cross(nm), nm;
      H += w * J * J.transpose();
      g += w * J * ri;
      ss += ri * ri;
    }
    const double rms = std::sqrt(ss / used);
    if (it == 0) res.summary.initial_rms_mm = rms;
    H_last = H;
    T_last = T;
    centre_last = centre;
    sigma_last = sigma;
    Eigen::MatrixXd A = H;
    Eigen::VectorXd rhs = -g;
    // MAP step: the prior weighted by the data's robust scale squared (the data term is
    // sum w r^2, the log-posterior sum w r^2 / sigma^2 + xi^T P xi).
    if (prior) add_pose_prior(*prior, T, centre, sigma * sigma, A, rhs);
    // Light Levenberg damping keeps the sliding directions of a flat patch bounded.
    A.diagonal().array() += 1e-9 * A.diagonal().maxCoeff() + 1e-12;
    const Eigen::Matrix<double, 6, 1> xi = A.ldlt().solve(rhs);
    const Eigen::Isometry3d step = Eigen::Translation3d(centre) * exp_se3(xi) * Eigen::Translation3d(-centre);
    T = step * T;
    const double step_mm = xi.tail<3>().norm() + xi.head<3>().norm() * extent;
    res.summary.history.push_back({rms, used, step_mm});
    res.summary.iterations = it + 1;
    res.summary.final_rms_mm = rms;
    res.summary.points_used = used;
    res.summary.points_trimmed = n - used;
    if (!xi.allFinite()) {
      res.summary.termination = "numerical failure";
      break;
    }
    if (step_mm < o.step_tolerance_mm) {
      res.summary.termination = "converged";
      break;
    }
    // No progress over 10 iterations (the pose wanders on data it cannot explain).
    const auto& h = res.summary.history;
    if (h.size() > 10 && h[h.size() - 11].rms_mm - rms < 1e-3 * h[h.size() - 11].rms_mm) {
      res.summary.termination = "stalled: no residual decrease in 10 iterations";
      break;
    }
  }
  // Final residuals at the returned pose.
  double ss = 0.0, mx = 0.0;
  int used = 0;
  for (int i = 0; i < n; ++i) {
    if (!keep[static_cast<std::size_t>(i)]) continue;
    const double d = index.closest(T * data_Intraop_mm.col(i)).distance_mm;
    ss += d * d;
    mx = std::max(mx, d);
    ++used;
  }
  if (used > 0) {
    res.summary.final_rms_mm = std::sqrt(ss / used);
    res.summary.final_max_mm = mx;
  }
  res.X_IntraopModel = T.inverse();
  res.X_IntraopModel_fit = res.X_IntraopModel;
  res.robust_scale_mm = sigma_last;
  if (sigma_last > 0) {
    res.posterior = pose_posterior(prior, T_last, centre_last, H_last, sigma_last * sigma_last);
    if (prior) {
      // Never worse against the prior: the result replaces the start only when it lowers
      // the MAP objective (robust data term at the final scale plus the prior).
      const Eigen::Isometry3d T0 = X_IntraopModel_initial.inverse();
      res.objective_start = icp_objective(index, data_Intraop_mm, T0, o, sigma_last) + prior_term(*prior, T0);
      res.objective_result = icp_objective(index, data_Intraop_mm, T, o, sigma_last) + prior_term(*prior, T);
      // (equal within rounding: ICP stayed at the start, nothing to judge)
      if (!(res.objective_result <= res.objective_start * (1.0 + 1e-12))) {
        res.start_kept = true;
        res.start_kept_reason = "the ICP pose does not lower the MAP objective (" + std::to_string(res.objective_result) + " against " +
                                std::to_string(res.objective_start) + " at the start)";
      } else if (o.noise_mm > 0 && res.summary.final_rms_mm > o.model_error_ratio * o.noise_mm) {
        res.start_kept = true;
        res.start_kept_reason = "the rigid model leaves model error (residual " + std::to_string(res.summary.final_rms_mm) + " mm RMS against " +
                                std::to_string(o.noise_mm) + " mm noise): a deformed organ biases a rigid fit on a partial surface";
      }
      if (res.start_kept) res.X_IntraopModel = X_IntraopModel_initial;
    }
  }
  res.summary.wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

}  // namespace arnav::host
