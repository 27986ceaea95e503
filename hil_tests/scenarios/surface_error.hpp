#pragma once
// 3-D errors of a drawn structure against the true one, in one frame (the camera's, mm):
// the centroid error split along / across the viewing ray, and the distance between two
// closed triangle surfaces (each vertex of one to the nearest point of the other's
// triangles, both ways: mean and max, i.e. the mean and the Hausdorff distance).
// Brute force (vertices x triangles): meant for tumours of a few hundred vertices.
#include <vector>

#include <Eigen/Core>

namespace arnav::hil {

struct CentroidError3d {
  double distance_mm = 0.0;   // |drawn - truth|
  double along_ray_mm = 0.0;  // (drawn - truth) . unit(truth): + the drawn one lies too far from the camera
  double across_ray_mm = 0.0; // the rest, perpendicular to the viewing ray
};

// Both points in the camera frame (origin at the camera centre); truth must not be the origin.
CentroidError3d centroid_error_3d(const Eigen::Vector3d& drawn_Cam_mm, const Eigen::Vector3d& truth_Cam_mm);

struct TriSurface {
  std::vector<Eigen::Vector3d> vertices_mm;
  std::vector<Eigen::Vector3i> triangles;
};

// Distance from p to the triangle (a, b, c) (closest point on the triangle, edges included).
double point_triangle_distance_mm(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                  const Eigen::Vector3d& c);

struct SurfaceDistance {
  double mean_mm = 0.0;  // mean over the vertices of both surfaces of the distance to the other
  double max_mm = 0.0;   // largest of those (symmetric Hausdorff distance at the vertices)
};

// Throws std::invalid_argument for an empty surface or a triangle index out of range.
SurfaceDistance surface_distance(const TriSurface& drawn, const TriSurface& truth);

}  // namespace arnav::hil
