#include "calibration/lib/pivot_calibration.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <random>
#include <sstream>

#include <Eigen/SVD>

#include "calibration/lib/calib_error.hpp"

namespace arnav::calib {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

struct LinearPivot {
  Eigen::Vector3d p_tip;
  Eigen::Vector3d p_pivot;
};

// Stacks [R_i | -I] [p_tip; p_pivot] = -t_i for the chosen poses.
Eigen::MatrixXd stacked_system(const std::vector<Eigen::Isometry3d>& X, const std::vector<int>& idx,
                               Eigen::VectorXd* rhs) {
  Eigen::MatrixXd A(3 * idx.size(), 6);
  if (rhs) rhs->resize(3 * static_cast<Eigen::Index>(idx.size()));
  for (std::size_t k = 0; k < idx.size(); ++k) {
    const auto& P = X[static_cast<std::size_t>(idx[k])];
    const Eigen::Index r = 3 * static_cast<Eigen::Index>(k);
    A.block<3, 3>(r, 0) = P.linear();
    A.block<3, 3>(r, 3) = -Eigen::Matrix3d::Identity();
    if (rhs) rhs->segment<3>(r) = -P.translation();
  }
  return A;
}

LinearPivot solve_algebraic(const std::vector<Eigen::Isometry3d>& X, const std::vector<int>& idx) {
  Eigen::VectorXd b;
  const Eigen::MatrixXd A = stacked_system(X, idx, &b);
  const Eigen::VectorXd x = A.jacobiSvd(Eigen::ComputeThinU | Eigen::ComputeThinV).solve(b);
  return {x.head<3>(), x.tail<3>()};
}

double residual(const Eigen::Isometry3d& X, const LinearPivot& s) {
  return (X.linear() * s.p_tip + X.translation() - s.p_pivot).norm();
}

// Linear sphere fit to the tool origins, refined geometrically (Gauss-Newton on centre
// and radius); the tip is then the mean of the origins' offsets seen in the tool frame.
LinearPivot solve_sphere(const std::vector<Eigen::Isometry3d>& X, SolverSummary& summary) {
  const auto n = static_cast<Eigen::Index>(X.size());
  Eigen::MatrixXd A(n, 4);
  Eigen::VectorXd b(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3d t = X[static_cast<std::size_t>(i)].translation();
    A.row(i) << 2.0 * t.transpose(), 1.0;
    b(i) = t.squaredNorm();
  }
  const Eigen::Vector4d s = A.jacobiSvd(Eigen::ComputeThinU | Eigen::ComputeThinV).solve(b);
  Eigen::Vector3d c = s.head<3>();
  double r = std::sqrt(std::max(0.0, s(3) + c.squaredNorm()));
  auto rms_of = [&](const Eigen::Vector3d& cc, double rr) {
    double sum = 0.0;
    for (const auto& P : X) sum += std::pow((P.translation() - cc).norm() - rr, 2);
    return std::sqrt(sum / static_cast<double>(X.size()));
  };
  summary.initial_cost = rms_of(c, r);
  summary.termination = "max iterations (50)";
  for (int it = 0; it < 50; ++it) {
    Eigen::MatrixXd J(n, 4);
    Eigen::VectorXd e(n);
    for (Eigen::Index i = 0; i < n; ++i) {
      const Eigen::Vector3d d = X[static_cast<std::size_t>(i)].translation() - c;
      const double len = std::max(d.norm(), 1e-12);
      e(i) = len - r;
      J.row(i) << -d.transpose() / len, -1.0;
    }
    const Eigen::Vector4d step = J.jacobiSvd(Eigen::ComputeThinU | Eigen::ComputeThinV).solve(-e);
    c += step.head<3>();
    r += step(3);
    summary.iterations = it + 1;
    if (step.norm() < 1e-9) {
      summary.termination = "converged: step < 1e-9 mm";
      break;
    }
  }
  summary.final_cost = rms_of(c, r);
  Eigen::Vector3d tip = Eigen::Vector3d::Zero();
  for (const auto& P : X) tip += P.linear().transpose() * (c - P.translation());
  tip /= static_cast<double>(X.size());
  return {tip, c};
}

}  // namespace

std::string to_string(PivotMethod m) {
  switch (m) {
    case PivotMethod::Algebraic: return "algebraic";
    case PivotMethod::SphereFit: return "sphere";
    case PivotMethod::Ransac: return "ransac";
  }
  return "unknown";
}

PivotMethod parse_pivot_method(const std::string& name) {
  if (name == "algebraic") return PivotMethod::Algebraic;
  if (name == "sphere") return PivotMethod::SphereFit;
  if (name == "ransac") return PivotMethod::Ransac;
  throw CalibError("pivot method '" + name + "' unknown (algebraic, sphere or ransac)");
}

Eigen::Matrix3d mean_rotation(const std::vector<Eigen::Matrix3d>& rotations) {
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  for (const auto& R : rotations) sum += R;
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixU() * D * svd.matrixV().transpose();
}

double rotation_spread_deg(const std::vector<Eigen::Isometry3d>& poses) {
  if (poses.empty()) return 0.0;
  std::vector<Eigen::Matrix3d> Rs;
  for (const auto& P : poses) Rs.push_back(P.linear());
  const Eigen::Matrix3d mean = mean_rotation(Rs);
  double worst = 0.0;
  for (const auto& R : Rs) {
    worst = std::max(worst, Eigen::AngleAxisd(mean.transpose() * R).angle() * kRadToDeg);
  }
  return worst;
}

PivotResult calibrate_pivot(const std::vector<Eigen::Isometry3d>& X, const PivotOptions& opt) {
  const auto start = std::chrono::steady_clock::now();
  const int n = static_cast<int>(X.size());
  if (n < std::max(opt.min_poses, 3)) {
    throw DegenerateInput("pivot: " + std::to_string(n) + " poses, at least " +
                          std::to_string(std::max(opt.min_poses, 3)) +
                          " needed: record more poses while pivoting the tool about its tip");
  }
  PivotResult res;
  std::vector<int> all(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) all[static_cast<std::size_t>(i)] = i;

  // Degeneracy is a property of the data, whatever the method: check it first.
  const Eigen::MatrixXd A = stacked_system(X, all, nullptr);
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(A);
  const Eigen::Matrix<double, 6, 1> sv = svd.singularValues();
  res.condition_number = sv(5) > 0.0 ? sv(0) / sv(5) : std::numeric_limits<double>::infinity();
  res.rank = 0;
  for (int i = 0; i < 6; ++i) {
    if (sv(i) > opt.rank_tolerance * sv(0)) ++res.rank;
  }
  res.rotation_spread_deg = rotation_spread_deg(X);
  if (res.rank < 6) {
    std::ostringstream msg;
    msg << "pivot: degenerate pose set: the stacked [R_i | -I] system has rank " << res.rank
        << " < 6 (the rotations do not span: e.g. all about one axis, which leaves the tip "
           "unobservable along it). Tilt the tool in two different directions (forward/back "
           "and left/right, 20-40 degrees) while keeping the tip in the divot.";
    throw DegenerateInput(msg.str());
  }
  if (res.rotation_spread_deg < opt.min_rotation_spread_deg) {
    std::ostringstream msg;
    msg.precision(3);
    msg << "pivot: too little rotation: the poses spread only " << res.rotation_spread_deg
        << " deg about their mean (at least " << opt.min_rotation_spread_deg
        << " deg needed). Tilt the tool more (20-40 degrees each way) while keeping the tip "
           "in the divot.";
    throw DegenerateInput(msg.str());
  }

  LinearPivot sol;
  res.inlier.assign(static_cast<std::size_t>(n), true);
  switch (opt.method) {
    case PivotMethod::Algebraic:
      sol = solve_algebraic(X, all);
      res.summary.method = "pivot: algebraic least squares ([R_i | -I] x = -t_i, SVD)";
      res.summary.termination = "closed form";
      break;
    case PivotMethod::SphereFit:
      sol = solve_sphere(X, res.summary);
      // Summary costs are the sphere's radial RMS (before/after Gauss-Newton); the pivot
      // residual of the result is rms_mm.
      res.summary.method = "pivot: sphere fit to tool origins (linear + Gauss-Newton)";
      break;
    case PivotMethod::Ransac: {
      std::mt19937 rng(opt.ransac_seed);
      std::uniform_int_distribution<int> pick(0, n - 1);
      std::vector<int> best;
      int it = 0;
      for (; it < opt.ransac_iterations; ++it) {
        std::vector<int> sample;
        while (sample.size() < 3) {
          const int k = pick(rng);
          if (std::find(sample.begin(), sample.end(), k) == sample.end()) sample.push_back(k);
        }
        // Three poses whose rotations barely differ give a meaningless hypothesis.
        Eigen::JacobiSVD<Eigen::MatrixXd> s3(stacked_system(X, sample, nullptr));
        if (s3.singularValues()(5) < 1e-3 * s3.singularValues()(0)) continue;
        const LinearPivot hyp = solve_algebraic(X, sample);
        std::vector<int> inl;
        for (int i = 0; i < n; ++i) {
          if (residual(X[static_cast<std::size_t>(i)], hyp) < opt.ransac_inlier_mm) inl.push_back(i);
        }
        if (inl.size() > best.size()) best = inl;
        if (static_cast<int>(best.size()) == n) break;
      }
      if (static_cast<int>(best.size()) < std::max(opt.min_poses, 3)) {
        throw DegenerateInput("pivot (RANSAC): only " + std::to_string(best.size()) + " of " +
                              std::to_string(n) + " poses agree within " +
                              std::to_string(opt.ransac_inlier_mm) +
                              " mm: the tip slipped in the divot or the tool was not tracked "
                              "well; record again");
      }
      sol = solve_algebraic(X, best);
      res.inlier.assign(static_cast<std::size_t>(n), false);
      for (int i : best) res.inlier[static_cast<std::size_t>(i)] = true;
      res.summary.method = "pivot: RANSAC (3-pose hypotheses, inlier < " +
                           std::to_string(opt.ransac_inlier_mm) + " mm) + algebraic refit";
      res.summary.iterations = it;
      res.summary.termination = std::to_string(best.size()) + "/" + std::to_string(n) + " inliers";
      break;
    }
  }
  res.p_ToolTip_mm = sol.p_tip;
  res.p_NdiPivot_mm = sol.p_pivot;
  double sum = 0.0;
  int count = 0;
  for (int i = 0; i < n; ++i) {
    const double e = residual(X[static_cast<std::size_t>(i)], sol);
    res.residual_mm.push_back(e);
    if (res.inlier[static_cast<std::size_t>(i)]) {
      sum += e * e;
      ++count;
      res.max_mm = std::max(res.max_mm, e);
    }
  }
  res.rms_mm = std::sqrt(sum / count);
  if (opt.method != PivotMethod::SphereFit) {
    res.summary.initial_cost = res.rms_mm;
    res.summary.final_cost = res.rms_mm;
  }
  res.summary.wall_time_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return res;
}

}  // namespace arnav::calib
