#include "host/scene/embedding.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "host/mesh/load_error.hpp"

namespace arnav::host {
namespace {

// Uniform grid over the tets' bounding boxes: each cell lists the tets overlapping it.
class TetGrid {
 public:
  explicit TetGrid(const TetMesh& mesh) {
    const auto& x = mesh.rest_positions_World_mm;
    lo_ = x.rowwise().minCoeff();
    const Eigen::Vector3d hi = x.rowwise().maxCoeff();
    const double volume = std::max((hi - lo_).prod(), 1e-30);
    // About 2 tets per cell on average.
    cell_ = std::cbrt(volume / std::max(1.0, mesh.num_tets() / 2.0));
    for (int k = 0; k < 3; ++k) n_[k] = std::clamp(static_cast<int>((hi[k] - lo_[k]) / cell_) + 1, 1, 512);
    cells_.resize(static_cast<std::size_t>(n_[0]) * n_[1] * n_[2]);
    for (int t = 0; t < mesh.num_tets(); ++t) {
      Eigen::Vector3d a = x.col(mesh.tets[t][0]), b = a;
      for (int v : mesh.tets[t]) {
        a = a.cwiseMin(x.col(v));
        b = b.cwiseMax(x.col(v));
      }
      const auto ia = cell_of(a), ib = cell_of(b);
      for (int i = ia[0]; i <= ib[0]; ++i)
        for (int j = ia[1]; j <= ib[1]; ++j)
          for (int k = ia[2]; k <= ib[2]; ++k) cells_[index(i, j, k)].push_back(t);
    }
  }
  std::array<int, 3> cell_of(const Eigen::Vector3d& p) const {
    std::array<int, 3> c{};
    // Clamp in floating point first: a point far outside the grid must not overflow int.
    for (int k = 0; k < 3; ++k) {
      const double f = std::floor((p[k] - lo_[k]) / cell_);
      c[k] = f >= 0.0 ? static_cast<int>(std::min(f, static_cast<double>(n_[k] - 1))) : 0;  // NaN -> 0
    }
    return c;
  }
  std::size_t index(int i, int j, int k) const { return (static_cast<std::size_t>(k) * n_[1] + j) * n_[0] + i; }
  const std::vector<int>& cell(const std::array<int, 3>& c) const { return cells_[index(c[0], c[1], c[2])]; }
  std::array<int, 3> dims() const { return n_; }
  double cell_size() const { return cell_; }

 private:
  Eigen::Vector3d lo_;
  double cell_ = 1.0;
  std::array<int, 3> n_{};
  std::vector<std::vector<int>> cells_;
};

Eigen::Vector4d barycentric(const TetMesh& mesh, int t, const Eigen::Vector3d& p) {
  const auto& x = mesh.rest_positions_World_mm;
  const auto& tet = mesh.tets[t];
  Eigen::Matrix3d D;
  for (int k = 0; k < 3; ++k) D.col(k) = x.col(tet[k + 1]) - x.col(tet[0]);
  const Eigen::Vector3d l = D.partialPivLu().solve(p - x.col(tet[0]));
  return Eigen::Vector4d(1.0 - l.sum(), l[0], l[1], l[2]);
}

// Distance from p to tet t (0 inside), via the closest point on its faces.
double distance_to_tet(const TetMesh& mesh, int t, const Eigen::Vector3d& p, const Eigen::Vector4d& w) {
  if (w.minCoeff() >= 0) return 0.0;
  const auto& x = mesh.rest_positions_World_mm;
  double best = std::numeric_limits<double>::infinity();
  for (const auto& f : kTetFaces) {
    // Closest point on triangle (Ericson, Real-Time Collision Detection 5.1.5).
    const Eigen::Vector3d a = x.col(mesh.tets[t][f[0]]), b = x.col(mesh.tets[t][f[1]]), c = x.col(mesh.tets[t][f[2]]);
    const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
    const double d1 = ab.dot(ap), d2 = ac.dot(ap);
    Eigen::Vector3d q;
    if (d1 <= 0 && d2 <= 0) {
      q = a;
    } else {
      const Eigen::Vector3d bp = p - b;
      const double d3 = ab.dot(bp), d4 = ac.dot(bp);
      const Eigen::Vector3d cp = p - c;
      const double d5 = ab.dot(cp), d6 = ac.dot(cp);
      const double vc = d1 * d4 - d3 * d2, vb = d5 * d2 - d1 * d6, va = d3 * d6 - d5 * d4;
      if (d3 >= 0 && d4 <= d3) q = b;
      else if (d6 >= 0 && d5 <= d6) q = c;
      else if (vc <= 0 && d1 >= 0 && d3 <= 0) q = a + ab * (d1 / (d1 - d3));
      else if (vb <= 0 && d2 >= 0 && d6 <= 0) q = a + ac * (d2 / (d2 - d6));
      else if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) q = b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
      else {
        const double den = 1.0 / (va + vb + vc);
        q = a + ab * (vb * den) + ac * (vc * den);
      }
    }
    best = std::min(best, (p - q).norm());
  }
  return best;
}

}  // namespace

Eigen::Matrix3Xd Embedding::apply(const TetMesh& mesh, const Eigen::Matrix3Xd& x) const {
  Eigen::Matrix3Xd out(3, size());
  for (int i = 0; i < size(); ++i) {
    const auto& t = mesh.tets[tet[i]];
    out.col(i) = weights(0, i) * x.col(t[0]) + weights(1, i) * x.col(t[1]) + weights(2, i) * x.col(t[2]) + weights(3, i) * x.col(t[3]);
  }
  return out;
}

MaterialPoint Embedding::material_point(const TetMesh& mesh, int i) const {
  MaterialPoint p;
  for (int k = 0; k < 4; ++k) {
    p.vertices.push_back(mesh.tets[tet[i]][k]);
    p.weights.push_back(weights(k, i));
  }
  return p;
}

Embedding embed_points(const TetMesh& mesh, const Eigen::Matrix3Xd& points, double tolerance_mm, const std::string& what) {
  Embedding e;
  e.tet.assign(points.cols(), -1);
  e.weights.resize(4, points.cols());
  if (mesh.num_tets() == 0) throw_load_error(what, 0, "cannot embed points in an empty volume mesh", "give a volume mesh");
  const TetGrid grid(mesh);
  const auto dims = grid.dims();
  for (int i = 0; i < points.cols(); ++i) {
    const Eigen::Vector3d p = points.col(i);
    if (!p.allFinite()) throw_load_error(what, 0, "point " + std::to_string(i) + " is not finite", "fix its coordinates");
    const auto c = grid.cell_of(p);
    int best = -1;
    double best_dist = std::numeric_limits<double>::infinity();
    Eigen::Vector4d best_w;
    // Search rings of cells outward until a containing tet is found; for points outside
    // the mesh, stop once the ring is beyond the best distance found.
    for (int ring = 0; ring <= std::max({dims[0], dims[1], dims[2]}); ++ring) {
      for (int di = -ring; di <= ring; ++di)
        for (int dj = -ring; dj <= ring; ++dj)
          for (int dk = -ring; dk <= ring; ++dk) {
            if (std::max({std::abs(di), std::abs(dj), std::abs(dk)}) != ring) continue;
            const std::array<int, 3> q{c[0] + di, c[1] + dj, c[2] + dk};
            if (q[0] < 0 || q[1] < 0 || q[2] < 0 || q[0] >= dims[0] || q[1] >= dims[1] || q[2] >= dims[2]) continue;
            for (int t : grid.cell(q)) {
              const Eigen::Vector4d w = barycentric(mesh, t, p);
              if (w.minCoeff() >= -1e-12) {
                best = t, best_dist = 0, best_w = w;
                break;
              }
              const double d = distance_to_tet(mesh, t, p, w);
              if (d < best_dist) best = t, best_dist = d, best_w = w;
            }
            if (best_dist == 0) break;
          }
      if (best_dist == 0) break;
      // A tet not met yet overlaps no cell of rings 0..ring, so it is at least
      // ring cell widths away: stop when the best is closer, or all are beyond tolerance.
      const double unseen_mm = ring * grid.cell_size();
      if (best_dist <= unseen_mm || unseen_mm > tolerance_mm) break;
    }
    if (best < 0 || best_dist > tolerance_mm) {
      std::ostringstream s;
      s << "point " << i << " (" << p.transpose() << ") lies " << best_dist << " mm outside the volume mesh (tolerance "
        << tolerance_mm << " mm)";
      throw_load_error(what, 0, s.str(), "move the structure inside the organ or correct its frame/scale");
    }
    e.tet[i] = best;
    e.weights.col(i) = best_w;
    e.max_outside_mm = std::max(e.max_outside_mm, best_dist);
  }
  return e;
}

}  // namespace arnav::host
