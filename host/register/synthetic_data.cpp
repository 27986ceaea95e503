#include "host/register/synthetic_data.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <numeric>

namespace arnav::host {

SampledPatch sample_patch(const Eigen::Matrix3Xd& x, const std::vector<std::array<int, 3>>& tris, const Eigen::Vector3d& seed,
                          const Eigen::Vector3d& view_dir, double coverage, double spacing_mm, std::mt19937& rng) {
  const int m = static_cast<int>(tris.size());
  std::vector<double> area(static_cast<std::size_t>(m)), dist(static_cast<std::size_t>(m));
  std::vector<Eigen::Vector3d> normal(static_cast<std::size_t>(m));
  double total = 0.0;
  for (int t = 0; t < m; ++t) {
    const auto& f = tris[static_cast<std::size_t>(t)];
    const Eigen::Vector3d a = x.col(f[0]), b = x.col(f[1]), c = x.col(f[2]);
    const Eigen::Vector3d n = (b - a).cross(c - a);
    area[static_cast<std::size_t>(t)] = 0.5 * n.norm();
    normal[static_cast<std::size_t>(t)] = n.normalized();
    dist[static_cast<std::size_t>(t)] = ((a + b + c) / 3.0 - seed).norm();
    total += area[static_cast<std::size_t>(t)];
  }
  std::vector<int> order(static_cast<std::size_t>(m));
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int i, int j) { return dist[static_cast<std::size_t>(i)] < dist[static_cast<std::size_t>(j)]; });
  SampledPatch p;
  double covered = 0.0;
  for (int t : order) {
    if (covered >= coverage * total) break;
    if (normal[static_cast<std::size_t>(t)].dot(view_dir) <= 0.0) continue;  // faces away from the viewer / pointer
    p.tris.push_back(t);
    covered += area[static_cast<std::size_t>(t)];
  }
  p.coverage = total > 0 ? covered / total : 0.0;
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<double> pts, nrm;
  for (int t : p.tris) {
    const double expected = area[static_cast<std::size_t>(t)] / (spacing_mm * spacing_mm);
    int count = static_cast<int>(std::floor(expected));
    if (u(rng) < expected - count) ++count;
    const auto& f = tris[static_cast<std::size_t>(t)];
    for (int k = 0; k < count; ++k) {
      double r1 = u(rng), r2 = u(rng);
      if (r1 + r2 > 1.0) {
        r1 = 1.0 - r1;
        r2 = 1.0 - r2;
      }
      const Eigen::Vector3d q = (1 - r1 - r2) * x.col(f[0]) + r1 * x.col(f[1]) + r2 * x.col(f[2]);
      pts.insert(pts.end(), {q.x(), q.y(), q.z()});
      const Eigen::Vector3d& n = normal[static_cast<std::size_t>(t)];
      nrm.insert(nrm.end(), {n.x(), n.y(), n.z()});
    }
  }
  p.points_mm = Eigen::Map<Eigen::Matrix3Xd>(pts.data(), 3, static_cast<Eigen::Index>(pts.size() / 3));
  p.normals = Eigen::Map<Eigen::Matrix3Xd>(nrm.data(), 3, static_cast<Eigen::Index>(nrm.size() / 3));
  return p;
}

void add_noise(Eigen::Matrix3Xd& points, double sigma_mm, std::mt19937& rng) {
  if (sigma_mm <= 0) return;
  std::normal_distribution<double> g(0.0, sigma_mm);
  for (int i = 0; i < points.cols(); ++i)
    for (int k = 0; k < 3; ++k) points(k, i) += g(rng);
}

int add_outliers(Eigen::Matrix3Xd& points, const Eigen::Matrix3Xd& around, double fraction, double margin_mm, double min_distance_mm,
                 std::mt19937& rng) {
  if (fraction <= 0 || around.cols() == 0) return 0;
  const int n = static_cast<int>(points.cols());
  const int count = static_cast<int>(std::lround(fraction * n / (1.0 - fraction)));
  const Eigen::Vector3d lo = around.rowwise().minCoeff().array() - margin_mm, hi = around.rowwise().maxCoeff().array() + margin_mm;
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Eigen::Matrix3Xd out(3, n + count);
  out.leftCols(n) = points;
  int added = 0, tries = 0;
  while (added < count && tries < 1000 * (count + 1)) {
    ++tries;
    Eigen::Vector3d q;
    for (int k = 0; k < 3; ++k) q[k] = lo[k] + u(rng) * (hi[k] - lo[k]);
    if ((around.colwise() - q).colwise().squaredNorm().minCoeff() < min_distance_mm * min_distance_mm) continue;
    out.col(n + added++) = q;
  }
  points = out.leftCols(n + added);
  return added;
}

Eigen::Isometry3d random_rigid(double angle_deg, double translation_mm, std::mt19937& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::Vector3d axis(g(rng), g(rng), g(rng)), dir(g(rng), g(rng), g(rng));
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = Eigen::AngleAxisd(angle_deg * std::numbers::pi / 180.0, axis.normalized()).toRotationMatrix();
  X.translation() = translation_mm * dir.normalized();
  return X;
}

}  // namespace arnav::host
