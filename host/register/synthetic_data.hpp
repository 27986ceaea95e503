#pragma once
// Synthetic intraoperative data for tests and the in-silico benchmark (arnav-bench
// register): partial surface patches sampled from a surface, noise, outliers, rigid
// offsets. Frames: whatever the surface is in. Units: mm.
#include <Eigen/Geometry>

#include <array>
#include <random>
#include <vector>

namespace arnav::host {

struct SampledPatch {
  Eigen::Matrix3Xd points_mm;
  Eigen::Matrix3Xd normals;    // surface normals at the samples (unit)
  std::vector<int> tris;       // triangles the patch covers
  double coverage = 0.0;       // patch area / surface area
};

// The connected-ish patch nearest to `seed_mm` (triangles by centroid distance, restricted
// to triangles whose normal faces `view_dir`, i.e. n . view_dir > 0) whose area reaches
// `coverage` of the whole surface; points sampled uniformly by area, one per
// spacing_mm^2 on average.
SampledPatch sample_patch(const Eigen::Matrix3Xd& x_mm, const std::vector<std::array<int, 3>>& tris, const Eigen::Vector3d& seed_mm,
                          const Eigen::Vector3d& view_dir, double coverage, double spacing_mm, std::mt19937& rng);

// Adds isotropic Gaussian noise (sigma_mm per axis).
void add_noise(Eigen::Matrix3Xd& points_mm, double sigma_mm, std::mt19937& rng);

// Appends round(fraction * n / (1 - fraction)) points uniform in the box of `around`
// grown by margin_mm, at least min_distance_mm from every point of `around` (so they are
// really outliers). Returns the count added.
int add_outliers(Eigen::Matrix3Xd& points_mm, const Eigen::Matrix3Xd& around, double fraction, double margin_mm,
                 double min_distance_mm, std::mt19937& rng);

// A rotation of exactly angle_deg about a random axis, and a translation of length
// translation_mm in a random direction.
Eigen::Isometry3d random_rigid(double angle_deg, double translation_mm, std::mt19937& rng);

}  // namespace arnav::host
