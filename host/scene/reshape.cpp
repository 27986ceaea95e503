#include "host/scene/reshape.hpp"

#include <Eigen/LU>

#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <random>
#include <stdexcept>

namespace arnav::host {
namespace {

// A smooth random displacement field: a sum of plane waves whose wavelength is half the
// organ's diagonal (shape error of a segmentation, not surface noise), unit-free until the
// caller scales it.
class SmoothWarp {
 public:
  SmoothWarp(double wavelength_mm, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> normal;
    std::uniform_real_distribution<double> phase(0.0, 2.0 * std::numbers::pi);
    for (Wave& w : waves_) {
      const Eigen::Vector3d direction = Eigen::Vector3d(normal(rng), normal(rng), normal(rng)).normalized();
      w.k_per_mm = (2.0 * std::numbers::pi / wavelength_mm) * direction;
      w.amplitude = Eigen::Vector3d(normal(rng), normal(rng), normal(rng));
      w.phase = phase(rng);
    }
  }
  Eigen::Vector3d operator()(const Eigen::Vector3d& p_mm) const {
    Eigen::Vector3d d = Eigen::Vector3d::Zero();
    for (const Wave& w : waves_) d += w.amplitude * std::sin(w.k_per_mm.dot(p_mm) + w.phase);
    return d;
  }

 private:
  struct Wave {
    Eigen::Vector3d k_per_mm, amplitude;
    double phase = 0.0;
  };
  std::array<Wave, 4> waves_;
};

void map_columns(Eigen::Matrix3Xd& x, const auto& map) {
  for (Eigen::Index i = 0; i < x.cols(); ++i) x.col(i) = map(Eigen::Vector3d(x.col(i)));
}

// The smallest ratio of a tet's volume after the map to its volume before.
double min_volume_ratio(const TetMesh& before, const Eigen::Matrix3Xd& after) {
  auto volume = [](const Eigen::Matrix3Xd& x, const std::array<int, 4>& t) {
    Eigen::Matrix3d d;
    for (int s = 0; s < 3; ++s) d.col(s) = x.col(t[s + 1]) - x.col(t[0]);
    return d.determinant();
  };
  double ratio = std::numeric_limits<double>::infinity();
  for (const auto& t : before.tets) ratio = std::min(ratio, volume(after, t) / volume(before.rest_positions_World_mm, t));
  return ratio;
}

}  // namespace

std::string describe(const SceneReshape& r) {
  char text[96];
  std::snprintf(text, sizeof text, "scale %g, warp %g mm (seed %u)", r.scale, r.warp_mm, r.seed);
  return text;
}

Scene reshaped_scene(const Scene& scene, const SceneReshape& r) {
  if (!(r.scale > 0.0) || !std::isfinite(r.scale))
    throw std::invalid_argument("mesh scale " + std::to_string(r.scale) + " must be a finite number > 0 (1: as loaded)");
  if (!(r.warp_mm >= 0.0) || !std::isfinite(r.warp_mm))
    throw std::invalid_argument("mesh warp " + std::to_string(r.warp_mm) + " mm must be a finite number >= 0 (0: none)");
  const Eigen::Matrix3Xd& x0 = scene.problem.mesh.rest_positions_World_mm;
  const Eigen::Vector3d centroid = x0.rowwise().mean();
  const double diagonal_mm = (x0.rowwise().maxCoeff() - x0.rowwise().minCoeff()).norm();
  const SmoothWarp warp(0.5 * diagonal_mm, r.seed);
  double largest = 0.0;
  for (Eigen::Index i = 0; i < x0.cols(); ++i) largest = std::max(largest, warp(x0.col(i)).norm());
  const double gain = largest > 0.0 ? r.warp_mm / largest : 0.0;
  const auto map = [&](const Eigen::Vector3d& p) -> Eigen::Vector3d {
    return centroid + r.scale * (p - centroid) + gain * warp(p);
  };

  Scene out = scene;
  map_columns(out.problem.mesh.rest_positions_World_mm, map);
  const double ratio = min_volume_ratio(scene.problem.mesh, out.problem.mesh.rest_positions_World_mm);
  if (!(ratio > 0.1 * r.scale * r.scale * r.scale))
    throw std::invalid_argument("mesh warp " + std::to_string(r.warp_mm) + " mm (seed " + std::to_string(r.seed) +
                                ") flattens or inverts a tet of " + scene.source + " (volume ratio " +
                                std::to_string(ratio) + "); use a smaller warp");
  map_columns(out.organ_surface.positions_World_mm, map);
  for (EmbeddedSurface& t : out.tumours) {
    map_columns(t.rest.positions_World_mm, map);
    t.rest_centroid_World_mm = map(t.rest_centroid_World_mm);
  }
  const auto reshape_vessels = [&](VesselTree& v) {
    map_columns(v.nodes_World_mm, map);
    for (double& radius : v.radius_mm) radius *= r.scale;
  };
  if (out.vessels) reshape_vessels(out.vessels->rest);
  if (out.problem.vessels) reshape_vessels(*out.problem.vessels);
  out.mesh_quality = tet_mesh_quality(out.problem.mesh);
  out.notes.push_back("reshaped: " + describe(r));
  out.source = scene.source + " (" + describe(r) + ")";
  return out;
}

}  // namespace arnav::host
