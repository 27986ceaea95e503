#include "host/register/load_basis.hpp"

#include <Eigen/CholmodSupport>
#include <Eigen/Dense>
#include <Eigen/Sparse>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "host/register/robust_stats.hpp"
#include "host/register/self_contact.hpp"
#include "host/register/surface_index.hpp"

namespace arnav::host {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Farthest-point sampling of k seeds among pts (deterministic: starts at the first point),
// then every point to its nearest seed. Returns the cluster index per point.
std::vector<int> cluster_points(const Eigen::Matrix3Xd& pts, int k) {
  const int n = static_cast<int>(pts.cols());
  k = std::clamp(k, 1, n);
  std::vector<int> seeds = {0};
  Eigen::VectorXd d = (pts.colwise() - pts.col(0)).colwise().norm().transpose();
  while (static_cast<int>(seeds.size()) < k) {
    Eigen::Index far = 0;
    d.maxCoeff(&far);
    seeds.push_back(static_cast<int>(far));
    d = d.cwiseMin((pts.colwise() - pts.col(far)).colwise().norm().transpose());
  }
  std::vector<int> label(static_cast<std::size_t>(n), 0);
  for (int i = 0; i < n; ++i) {
    double best = std::numeric_limits<double>::infinity();
    for (int s = 0; s < k; ++s) {
      const double dd = (pts.col(i) - pts.col(seeds[static_cast<std::size_t>(s)])).squaredNorm();
      if (dd < best) {
        best = dd;
        label[static_cast<std::size_t>(i)] = s;
      }
    }
  }
  return label;
}

struct Pairs {
  std::vector<SurfaceHit> hit;
  std::vector<int> kept;  // indices of kept points
  double rms = 0.0;       // over kept, point-to-surface distance
};

Pairs correspond(const SurfaceIndex& index, const Eigen::Matrix3Xd& q, double keep_fraction, double max_distance_mm) {
  Pairs p;
  const int n = static_cast<int>(q.cols());
  p.hit.resize(static_cast<std::size_t>(n));
  std::vector<double> dist(static_cast<std::size_t>(n));
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    p.hit[static_cast<std::size_t>(i)] = index.closest(q.col(i), max_distance_mm);
    dist[static_cast<std::size_t>(i)] = p.hit[static_cast<std::size_t>(i)].distance_mm;
  }
  if (n == 0) return p;
  const double d_keep = kth_value(dist, keep_fraction);
  double ss = 0.0;
  for (int i = 0; i < n; ++i) {
    const double d = dist[static_cast<std::size_t>(i)];
    if (p.hit[static_cast<std::size_t>(i)].tri >= 0 && d <= d_keep && d <= max_distance_mm) {
      p.kept.push_back(i);
      ss += d * d;
    }
  }
  p.rms = p.kept.empty() ? 0.0 : std::sqrt(ss / static_cast<double>(p.kept.size()));
  return p;
}

}  // namespace

LoadBasis build_load_basis(const Scene& scene, const LoadBasisOptions& o) {
  const auto t0 = Clock::now();
  const TetMesh& mesh = scene.problem.mesh;
  const int nv = mesh.num_vertices();
  if (mesh.num_tets() == 0 || nv < 4) throw std::invalid_argument("load basis: the scene's volume has no tets");
  const auto& mats = scene.problem.region_materials;
  LoadBasis b;
  b.dofs = 3 * nv;
  // Linear elastic stiffness at rest and lumped masses.
  std::vector<Eigen::Triplet<double>> trip;
  trip.reserve(static_cast<std::size_t>(mesh.num_tets()) * 144);
  Eigen::VectorXd mass = Eigen::VectorXd::Zero(nv);
  const Eigen::Matrix3Xd& X = mesh.rest_positions_World_mm;
  for (int t = 0; t < mesh.num_tets(); ++t) {
    const auto& tet = mesh.tets[static_cast<std::size_t>(t)];
    const int region = mesh.tet_region.empty() ? 0 : mesh.tet_region[static_cast<std::size_t>(t)];
    if (region < 0 || region >= static_cast<int>(mats.size()))
      throw std::invalid_argument("load basis: tet " + std::to_string(t) + " is in region " + std::to_string(region) + " without a material");
    const Material& m = mats[static_cast<std::size_t>(region)];
    Eigen::Matrix3d Dm;
    for (int a = 0; a < 3; ++a) Dm.col(a) = X.col(tet[static_cast<std::size_t>(a + 1)]) - X.col(tet[0]);
    const double det = Dm.determinant();
    const double vol = std::abs(det) / 6.0;
    if (!(vol > 1e-12)) throw std::invalid_argument("load basis: tet " + std::to_string(t) + " is degenerate (volume " + std::to_string(vol) + " mm^3)");
    const Eigen::Matrix3d Gi = Dm.inverse();  // rows: gradients of the shape functions 1..3
    Eigen::Matrix<double, 3, 4> g;
    for (int a = 0; a < 3; ++a) g.col(a + 1) = Gi.row(a).transpose();
    g.col(0) = -(g.col(1) + g.col(2) + g.col(3));
    const double E = m.youngs_modulus_kPa, nu = m.poisson_ratio;
    const double lam = E * nu / ((1 + nu) * (1 - 2 * nu)), mu = E / (2 * (1 + nu));
    for (int a = 0; a < 4; ++a)
      for (int c = 0; c < 4; ++c) {
        const Eigen::Matrix3d k =
            vol * (lam * g.col(a) * g.col(c).transpose() + mu * g.col(c) * g.col(a).transpose() + mu * g.col(a).dot(g.col(c)) * Eigen::Matrix3d::Identity());
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) trip.emplace_back(3 * tet[static_cast<std::size_t>(a)] + i, 3 * tet[static_cast<std::size_t>(c)] + j, k(i, j));
      }
    for (int v : tet) mass[v] += m.density_kg_per_mm3 * vol / 4.0;
    b.stiffness_volume += E * vol;
  }
  Eigen::SparseMatrix<double> K(b.dofs, b.dofs);
  K.setFromTriplets(trip.begin(), trip.end());

  // Free and supported dofs.
  std::vector<char> fixed(static_cast<std::size_t>(nv), 0);
  for (int v : scene.problem.fixed_vertices)
    if (v >= 0 && v < nv) fixed[static_cast<std::size_t>(v)] = 1;
  b.supported = std::any_of(fixed.begin(), fixed.end(), [](char c) { return c != 0; });
  std::vector<int> free_index(static_cast<std::size_t>(b.dofs), -1);
  std::vector<int> free_dofs;
  for (int v = 0; v < nv; ++v)
    if (!fixed[static_cast<std::size_t>(v)])
      for (int i = 0; i < 3; ++i) {
        free_index[static_cast<std::size_t>(3 * v + i)] = static_cast<int>(free_dofs.size());
        free_dofs.push_back(3 * v + i);
      }
  const int nf = static_cast<int>(free_dofs.size());
  std::vector<Eigen::Triplet<double>> tff;
  Eigen::SparseMatrix<double> Kfs_full(nf, b.dofs);  // free rows, all columns (for prescribed support motion)
  {
    std::vector<Eigen::Triplet<double>> tfs;
    for (int k = 0; k < K.outerSize(); ++k)
      for (Eigen::SparseMatrix<double>::InnerIterator it(K, k); it; ++it) {
        const int r = free_index[static_cast<std::size_t>(it.row())];
        if (r < 0) continue;
        const int c = free_index[static_cast<std::size_t>(it.col())];
        if (c >= 0) tff.emplace_back(r, c, it.value());
        else tfs.emplace_back(r, static_cast<int>(it.col()), it.value());
      }
    Kfs_full.setFromTriplets(tfs.begin(), tfs.end());
  }
  Eigen::SparseMatrix<double> Kff(nf, nf);
  Kff.setFromTriplets(tff.begin(), tff.end());
  if (!b.supported) {
    // No support declared: hold the mesh weakly (springs to rest of 1e-6 of the mean
    // diagonal) so the factor exists; the rigid part of every mode is removed below.
    const double eps = 1e-6 * Kff.diagonal().mean();
    for (int i = 0; i < nf; ++i) Kff.coeffRef(i, i) += eps;
  }
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>> llt;
  llt.compute(Kff);
  if (llt.info() != Eigen::Success) throw std::invalid_argument("load basis: the linear elastic stiffness could not be factorised (is the mesh connected and are the materials positive?)");

  // Surface vertices outside the support, lumped areas.
  Eigen::VectorXd area = Eigen::VectorXd::Zero(nv);
  for (const auto& f : mesh.surface_tris) {
    const double a = 0.5 * (X.col(f[1]) - X.col(f[0])).cross(X.col(f[2]) - X.col(f[0])).norm();
    for (int v : f) area[v] += a / 3.0;
  }
  std::vector<int> surf;
  for (int v = 0; v < nv; ++v)
    if (area[v] > 0 && !fixed[static_cast<std::size_t>(v)]) surf.push_back(v);
  if (surf.size() < 4) throw std::invalid_argument("load basis: fewer than 4 surface vertices outside the supported (fixed) region");
  Eigen::Matrix3Xd sp(3, static_cast<Eigen::Index>(surf.size()));
  for (std::size_t i = 0; i < surf.size(); ++i) sp.col(static_cast<Eigen::Index>(i)) = X.col(surf[i]);
  const std::vector<int> patch = cluster_points(sp, o.patches);
  b.patches = std::min<int>(std::max(o.patches, 1), static_cast<int>(surf.size()));
  b.patch_of_vertex.assign(static_cast<std::size_t>(nv), -1);
  std::vector<double> patch_area(static_cast<std::size_t>(b.patches), 0.0);
  for (std::size_t i = 0; i < surf.size(); ++i) {
    b.patch_of_vertex[static_cast<std::size_t>(surf[i])] = patch[i];
    patch_area[static_cast<std::size_t>(patch[i])] += area[surf[i]];
  }
  // Right-hand sides (free dofs) and prescribed support motions (all dofs).
  std::vector<int> support_vertices;
  for (int v = 0; v < nv; ++v)
    if (fixed[static_cast<std::size_t>(v)]) support_vertices.push_back(v);
  const int nsc = b.supported && o.support_clusters > 0 ? std::min<int>(o.support_clusters, static_cast<int>(support_vertices.size())) : 0;
  // Without a support a uniform body force only translates the body: no gravity modes.
  b.gravity = o.gravity_modes && b.supported ? 3 : 0;
  // Cluster 0 stays: moving all clusters alike is a rigid translation (the pose's, with no
  // strain energy to regularise it).
  b.support = nsc >= 2 ? 3 * (nsc - 1) : 0;
  const int m = 3 * b.patches + b.gravity + b.support;
  Eigen::MatrixXd F = Eigen::MatrixXd::Zero(nf, m);
  Eigen::MatrixXd Us = Eigen::MatrixXd::Zero(b.dofs, m);  // prescribed support displacements
  const char* axis = "xyz";
  for (int p = 0; p < b.patches; ++p)
    for (int i = 0; i < 3; ++i) b.mode_kind.push_back("patch " + std::to_string(p) + " " + axis[i]);
  for (std::size_t s = 0; s < surf.size(); ++s) {
    const int v = surf[s];
    const int p = patch[s];
    for (int i = 0; i < 3; ++i) F(free_index[static_cast<std::size_t>(3 * v + i)], 3 * p + i) = area[v] / patch_area[static_cast<std::size_t>(p)];
  }
  int col = 3 * b.patches;
  if (b.gravity > 0) {
    for (int i = 0; i < 3; ++i, ++col) {
      b.mode_kind.push_back(std::string("gravity ") + axis[i]);
      for (int v = 0; v < nv; ++v)
        if (!fixed[static_cast<std::size_t>(v)]) F(free_index[static_cast<std::size_t>(3 * v + i)], col) = mass[v];
    }
  }
  if (b.support > 0) {
    Eigen::Matrix3Xd fp(3, static_cast<Eigen::Index>(support_vertices.size()));
    for (std::size_t i = 0; i < support_vertices.size(); ++i) fp.col(static_cast<Eigen::Index>(i)) = X.col(support_vertices[i]);
    const std::vector<int> cl = cluster_points(fp, nsc);
    for (int c = 1; c < nsc; ++c)
      for (int i = 0; i < 3; ++i, ++col) {
        b.mode_kind.push_back("support " + std::to_string(c) + " " + axis[i]);
        for (std::size_t k = 0; k < support_vertices.size(); ++k)
          if (cl[k] == c) Us(3 * support_vertices[k] + i, col) = 1.0;
      }
  }
  const Eigen::MatrixXd rhs = F - Kfs_full * Us;
  const Eigen::MatrixXd uf = llt.solve(rhs);
  b.U = Us;
  for (int r = 0; r < nf; ++r) b.U.row(free_dofs[static_cast<std::size_t>(r)]) = uf.row(r);
  if (!b.supported) {
    // Remove each mode's best infinitesimal rigid motion (least squares over all vertices).
    Eigen::MatrixXd R(b.dofs, 6);
    const Eigen::Vector3d c = X.rowwise().mean();
    for (int v = 0; v < nv; ++v) {
      const Eigen::Vector3d p = X.col(v) - c;
      Eigen::Matrix3d skew;
      skew << 0, p.z(), -p.y(), -p.z(), 0, p.x(), p.y(), -p.x(), 0;  // omega x p = skew * omega
      R.block(3 * v, 0, 3, 3) = skew;
      R.block(3 * v, 3, 3, 3).setIdentity();
    }
    const Eigen::MatrixXd coef = R.colPivHouseholderQr().solve(b.U);
    b.U -= R * coef;
  }
  // Scale every mode to a largest vertex displacement of 1 mm.
  for (int j = 0; j < m; ++j) {
    double mx = 0.0;
    for (int v = 0; v < nv; ++v) mx = std::max(mx, b.U.block(3 * v, j, 3, 1).norm());
    if (!(mx > 0) || !std::isfinite(mx)) throw std::invalid_argument("load basis: mode '" + b.mode_kind[static_cast<std::size_t>(j)] + "' has no response");
    b.U.col(j) /= mx;
  }
  b.G = b.U.transpose() * (K * b.U);
  b.G = 0.5 * (b.G + b.G.transpose());
  b.build_time_s = seconds_since(t0);
  return b;
}

namespace {

constexpr int kMinPoints = 20;  // fewer usable points than this cannot support a deformation

// Landmark bound to the closest point of the volume's surface at rest (its displacement
// interpolated there), the offset of the landmark from that point kept.
struct LandmarkBinding {
  std::array<int, 3> v{};
  Eigen::Vector3d bary = Eigen::Vector3d::Zero();
  Eigen::Vector3d p_rest = Eigen::Vector3d::Zero();
  Eigen::Vector3d target = Eigen::Vector3d::Zero();
  Eigen::MatrixXd U;  // 3 x modes: the basis interpolated at the bound point
};

// Point-to-plane rows of the kept correspondences: residuals, robust (Huber) weights and
// the Jacobian [pose | basis weights].
struct DataRows {
  Eigen::VectorXd r, w;
  Eigen::MatrixXd J;
  double sigma = 0.0;                               // robust scale of the residuals, mm
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  // of the data: the pose step's centre
};

// The load-basis fit's state and steps: pose D, basis weights alpha and positions x, fitted
// by regularised Gauss-Newton level by level (fit_load_basis).
class LoadFit {
 public:
  LoadFit(const TetMesh& mesh, const LoadBasis& basis, const Eigen::Matrix3Xd& data, const std::vector<LandmarkPair>& landmarks,
          const LoadFitOptions& o)
      : mesh_(mesh), basis_(basis), data_(data), o_(o), rest_(mesh.rest_positions_World_mm), m_(basis.modes()),
        np_(o.estimate_pose ? 6 : 0), noise_(std::max(o.noise_mm, 1e-6)), s_axis_(o.landmark_error_mm / std::sqrt(3.0)),
        map_prior_(o.prior_strain > 0 && basis.stiffness_volume > 0), alpha_(Eigen::VectorXd::Zero(m_)), x_(rest_) {
    if (o.landmark_error_mm > 0) bind_landmarks(landmarks);
    // Held supports: the support modes (prescribed translations of support clusters, 1 mm
    // each) get a Gaussian prior of support_sigma_mm.
    if (o.support_sigma_mm > 0)
      for (int j = 0; j < m_; ++j)
        if (basis.mode_kind[static_cast<std::size_t>(j)].rfind("support", 0) == 0) support_modes_.push_back(j);
  }

  int landmarks() const { return static_cast<int>(lms_.size()); }

  double landmark_rms(const Eigen::Isometry3d& D, const Eigen::VectorXd& a) const {
    if (lms_.empty()) return 0.0;
    double ss = 0.0;
    for (const auto& b : lms_) ss += (D * b.target - b.p_rest - b.U * a).squaredNorm();
    return std::sqrt(ss / static_cast<double>(lms_.size()));
  }

  // The schedule's misfit (discrepancy, plateau, acceptance): the normalised chi of all
  // measurements, sqrt((sum d^2 / noise^2 + sum |e|^2 / s_l^2) / (points + 3 landmarks)),
  // s_l the landmark error per coordinate (Morozov's principle on the whole measurement
  // vector). Without landmarks it is the data RMS over the noise, so the rules read as on
  // the data RMS alone. (Counting the two groups alike, which lets three landmarks weigh
  // as much as a thousand points, made the benchmark worse: 2.90 against 2.60 mm.)
  double chi(const Pairs& pr, double lm_rms) const {
    const double nd = static_cast<double>(pr.kept.size());
    double num = nd * (pr.rms / noise_) * (pr.rms / noise_), den = nd;
    if (!lms_.empty()) {
      const double nl = static_cast<double>(lms_.size());
      num += nl * (lm_rms / s_axis_) * (lm_rms / s_axis_);
      den += 3.0 * nl;
    }
    return den > 0 ? std::sqrt(num / den) : 0.0;
  }
  bool at_noise(const Pairs& pr, double lm_rms) const { return chi(pr, lm_rms) <= o_.discrepancy_factor; }

  // Fills the rigid fit's residual; returns why the rigid result is kept when the data do
  // not call for a deformation (too few points, already at the noise), empty otherwise.
  std::string rigid_fit_suffices(LoadFitResult& res) {
    const SurfaceIndex idx(rest_, mesh_.surface_tris);
    const Pairs p0 = correspond(idx, data_, o_.keep_fraction, o_.max_distance_mm);
    res.rigid_rms_mm = p0.rms;
    res.final_rms_mm = p0.rms;
    if (static_cast<int>(p0.kept.size()) < kMinPoints)
      return "data does not support a non-rigid fit: " + std::to_string(p0.kept.size()) + " usable points (of " + std::to_string(data_.cols()) +
             ") within " + std::to_string(o_.max_distance_mm) + " mm of the rigidly registered model; the rigid result is kept";
    rigid_chi_ = chi(p0, res.landmark_rigid_rms_mm);
    if (at_noise(p0, res.landmark_rigid_rms_mm))
      return "the rigid fit already reaches the expected noise (" + std::to_string(p0.rms) + " mm RMS <= " + std::to_string(o_.noise_mm) + " mm" +
             (lms_.empty() ? std::string() : ", landmarks " + std::to_string(res.landmark_rigid_rms_mm) + " mm RMS") +
             "): no deformation needed; the rigid result is kept";
    return {};
  }

  // The MAP objective in units of noise^2 (docs/register.md, "Never worse, judged against
  // the prior"): robust data term over all points (capped), strain prior, pose prior, held
  // supports, landmarks.
  double objective(const Eigen::Isometry3d& D, const Eigen::VectorXd& a, const Eigen::Matrix3Xd& x) const {
    const SurfaceIndex idx(x, mesh_.surface_tris);
    const Eigen::Matrix3Xd q = D * data_;
    const int n = static_cast<int>(q.cols());
    std::vector<double> d(static_cast<std::size_t>(n));
#pragma omp parallel for schedule(static)
    for (int i = 0; i < n; ++i) {
      const SurfaceHit h = idx.closest(q.col(i), o_.max_distance_mm);
      d[static_cast<std::size_t>(i)] = h.tri >= 0 ? std::min(h.distance_mm, o_.max_distance_mm) : o_.max_distance_mm;
    }
    const double c = o_.huber_sigmas * noise_;
    double sum = 0.0;
    for (double r : d) sum += r <= c ? r * r : 2.0 * c * r - c * c;
    sum /= noise_ * noise_;
    if (map_prior_) sum += a.dot(basis_.G * a) / (basis_.stiffness_volume * o_.prior_strain * o_.prior_strain);
    if (o_.pose_prior) {
      const Vector6d xi = pose_deviation(*o_.pose_prior, D);
      sum += xi.dot(o_.pose_prior->information() * xi);
    }
    for (int j : support_modes_) sum += a[j] * a[j] / (o_.support_sigma_mm * o_.support_sigma_mm);
    for (const auto& b : lms_) sum += (D * b.target - b.p_rest - b.U * a).squaredNorm() / (s_axis_ * s_axis_);
    return sum;
  }

  // Stiff to flexible: lambda falls level by level; each level iterates to convergence
  // (correspondences recomputed every iteration). Discrepancy principle: the first level
  // whose residual reaches the expected noise ends the schedule; a level that lowers the
  // residual by less than min_improvement is a plateau (the basis explains no more of the
  // data: model error, not noise) and the previous, stiffer level is kept. With the MAP
  // prior every level is kept and the prior's weight is the last.
  void run_schedule(Clock::time_point t0, LoadFitResult& res) {
    Kept kept{rigid_chi_, alpha_, D_, x_};
    bool moved = false;
    // MAP prior: the absolute weight noise^2 / (sum(E V) strain^2); in relative units once
    // the data term's scale is known (first iteration).
    const double prior_abs = map_prior_ ? noise_ * noise_ / (basis_.stiffness_volume * o_.prior_strain * o_.prior_strain) : 0.0;
    bool last_level = false;
    for (double level_lambda : o_.lambda_schedule) {
      if (last_level) break;
      double lambda = level_lambda;
      if (map_prior_ && hscale_ > 0 && lambda <= prior_abs / hscale_) {
        lambda = prior_abs / hscale_;  // the prior's level: the last
        last_level = true;
      }
      if (o_.time_budget_s > 0 && seconds_since(t0) > o_.time_budget_s) {
        stop_ = "time budget reached";
        break;
      }
      if (!run_level(lambda, res)) break;
      const SurfaceIndex idx(x_, mesh_.surface_tris);
      const Pairs pl = correspond(idx, D_ * data_, o_.keep_fraction, o_.max_distance_mm);
      const double lm_level = landmark_rms(D_, alpha_);
      const double level_chi = chi(pl, lm_level);
      res.level_rms_mm.push_back(pl.rms);
      res.level_lambda.push_back(lambda);
      const bool gain = map_prior_ || level_chi <= kept.chi * (1.0 - o_.plateau_improvement);
      if (!gain && moved) {
        stop_ = "residual stopped improving (plateau above the noise: model error)";
        break;  // keep the previous level
      }
      if (!gain) continue;  // still too stiff to move: next level
      moved = true;
      kept = Kept{level_chi, alpha_, D_, x_};
      res.lambda = lambda;
      if (map_prior_) {
        res.prior_lambda = prior_abs / hscale_;
        if (last_level) stop_ = "reached the prior's regularisation";
      } else if (at_noise(pl, lm_level)) {
        stop_ = "reached the expected noise level";
        break;
      }
      if (total_ >= o_.max_iterations) {
        stop_ = "max_iterations";
        break;
      }
    }
    alpha_ = kept.alpha;
    D_ = kept.D;
    x_ = kept.x;
  }

  // The result: accepted when it lowers the rigid misfit by min_improvement and the MAP
  // objective (never worse than rigid, judged against the priors).
  void conclude(Clock::time_point t0, LoadFitResult& res) const {
    const SurfaceIndex idx(x_, mesh_.surface_tris);
    const Pairs pf = correspond(idx, D_ * data_, o_.keep_fraction, o_.max_distance_mm);
    res.final_rms_mm = pf.rms;
    res.wall_time_s = seconds_since(t0);
    const double final_chi = chi(pf, landmark_rms(D_, alpha_));
    res.objective_fit = objective(D_, alpha_, x_);
    if (np_ && scale_pose_ > 0)
      res.posterior = pose_posterior(o_.pose_prior ? &*o_.pose_prior : nullptr, D_, centre_pose_, H_pose_, scale_pose_ * scale_pose_);
    const bool objective_lower = res.objective_fit < res.objective_rigid;
    if (static_cast<int>(pf.kept.size()) >= kMinPoints && final_chi < rigid_chi_ * (1.0 - o_.min_improvement) && x_.allFinite() && objective_lower) {
      accept(res);
    } else {
      res.message = "data does not support a non-rigid fit (surface residual " + std::to_string(res.rigid_rms_mm) + " mm rigid, " +
                    std::to_string(pf.rms) + " mm with the load basis; MAP objective " + std::to_string(res.objective_rigid) + " rigid, " +
                    std::to_string(res.objective_fit) + " fitted" + (objective_lower ? "" : " (not lower against the priors)") + "; " + stop_ +
                    "); the rigid result is kept";
      res.final_rms_mm = res.rigid_rms_mm;
    }
  }

 private:
  struct Kept {  // the level kept: its misfit, weights, pose and shape
    double chi;
    Eigen::VectorXd alpha;
    Eigen::Isometry3d D;
    Eigen::Matrix3Xd x;
  };

  void bind_landmarks(const std::vector<LandmarkPair>& landmarks) {
    const SurfaceIndex idx(rest_, mesh_.surface_tris);
    for (const LandmarkPair& l : landmarks) {
      const SurfaceHit h = idx.closest(l.p_Model_mm);
      if (h.tri < 0 || !l.target_Model_mm.allFinite()) continue;
      LandmarkBinding b;
      const auto& f = mesh_.surface_tris[static_cast<std::size_t>(h.tri)];
      for (int a = 0; a < 3; ++a) b.v[static_cast<std::size_t>(a)] = f[static_cast<std::size_t>(a)];
      b.bary = Eigen::Vector3d(h.barycentric[0], h.barycentric[1], h.barycentric[2]);
      b.p_rest = l.p_Model_mm;
      b.target = l.target_Model_mm;
      b.U = Eigen::MatrixXd::Zero(3, m_);
      for (int a = 0; a < 3; ++a) b.U.noalias() += b.bary[a] * basis_.U.middleRows(3 * b.v[static_cast<std::size_t>(a)], 3);
      lms_.push_back(std::move(b));
    }
  }

  // One level: Gauss-Newton iterations until the step is below converged_step_mm. False
  // when the schedule must end (too few points, a numerical failure: stop_ says which).
  bool run_level(double lambda, LoadFitResult& res) {
    beta_ = 1.0;
    prev_step_.resize(0);
    for (int it = 0; it < o_.iterations_per_level && total_ < o_.max_iterations; ++it, ++total_) {
      LoadFitIteration rec;
      if (!iterate(lambda, rec)) {
        if (stop_ != "numerical failure") stop_ = "too few points";
        return false;
      }
      res.iterations.push_back(rec);
      if (rec.step_pose_mm < o_.converged_step_mm && rec.step_shape_mm < o_.converged_step_mm) break;
    }
    return true;
  }

  DataRows data_rows(const Pairs& pr, const Eigen::Matrix3Xd& q) const {
    const int n = static_cast<int>(pr.kept.size());
    DataRows d;
    d.r.resize(n);
    d.w.resize(n);
    std::vector<double> absr(static_cast<std::size_t>(n));
    for (int k = 0; k < n; ++k) {
      const int i = pr.kept[static_cast<std::size_t>(k)];
      const SurfaceHit& h = pr.hit[static_cast<std::size_t>(i)];
      d.r[k] = h.normal.dot(q.col(i) - h.point);
      absr[static_cast<std::size_t>(k)] = std::abs(d.r[k]);
    }
    d.sigma = std::max(o_.min_sigma_mm, 1.4826 * kth_value(absr, 0.5));
    const double hub = o_.huber_sigmas * d.sigma;
    for (int k = 0; k < n; ++k) d.w[k] = std::abs(d.r[k]) <= hub ? 1.0 : hub / std::abs(d.r[k]);
    d.centre = q.rowwise().mean();
    d.J.resize(n, np_ + m_);
    for (int k = 0; k < n; ++k) {
      const int i = pr.kept[static_cast<std::size_t>(k)];
      const SurfaceHit& h = pr.hit[static_cast<std::size_t>(i)];
      if (np_) {
        d.J.block<1, 3>(k, 0) = (q.col(i) - d.centre).cross(h.normal).transpose();
        d.J.block<1, 3>(k, 3) = h.normal.transpose();
      }
      const auto& f = mesh_.surface_tris[static_cast<std::size_t>(h.tri)];
      Eigen::RowVectorXd row = Eigen::RowVectorXd::Zero(m_);
      for (int a = 0; a < 3; ++a) row.noalias() += h.barycentric[a] * (h.normal.transpose() * basis_.U.middleRows(3 * f[static_cast<std::size_t>(a)], 3));
      d.J.block(k, np_, 1, m_) = -row;
    }
    return d;
  }

  // Landmark term, residual e = D q - (p + U_l alpha); weight from the data's robust scale
  // (s_data) against the landmark error per coordinate, Huber on |e|.
  void add_landmark_terms(double s_data, const Eigen::Vector3d& centre, Eigen::MatrixXd& A, Eigen::VectorXd& rhs) const {
    const double wl0 = (s_data * s_data) / (s_axis_ * s_axis_);
    for (const LandmarkBinding& b : lms_) {
      const Eigen::Vector3d ql = D_ * b.target;
      const Eigen::Vector3d e = ql - b.p_rest - b.U * alpha_;
      const double en = e.norm(), hl = 2.0 * o_.landmark_error_mm;
      const double wl = wl0 * (en <= hl ? 1.0 : hl / en);
      Eigen::MatrixXd Jl = Eigen::MatrixXd::Zero(3, np_ + m_);
      if (np_) {
        const Eigen::Vector3d a = ql - centre;
        Eigen::Matrix3d skew;
        skew << 0, -a.z(), a.y(), a.z(), 0, -a.x(), -a.y(), a.x(), 0;  // skew * b = a x b
        Jl.block<3, 3>(0, 0) = -skew;  // d(omega x a)/d omega
        Jl.block<3, 3>(0, 3).setIdentity();
      }
      Jl.rightCols(m_) = -b.U;
      A.noalias() += wl * Jl.transpose() * Jl;
      rhs.noalias() -= wl * Jl.transpose() * e;
    }
  }

  // One Gauss-Newton iteration at regularisation weight lambda: correspondences at the
  // current state, then the regularised step. Returns false when too few points remain or
  // the step is not finite.
  bool iterate(double lambda, LoadFitIteration& rec) {
    const Eigen::Matrix3Xd q = D_ * data_;
    const SurfaceIndex idx(x_, mesh_.surface_tris);
    const Pairs pr = correspond(idx, q, o_.keep_fraction, o_.max_distance_mm);
    if (static_cast<int>(pr.kept.size()) < kMinPoints) return false;
    const DataRows d = data_rows(pr, q);
    const Eigen::MatrixXd Jw = d.w.cwiseSqrt().asDiagonal() * d.J;
    const Eigen::VectorXd rw = d.w.cwiseSqrt().cwiseProduct(d.r);
    Eigen::MatrixXd H = Eigen::MatrixXd::Zero(np_ + m_, np_ + m_);
    H.selfadjointView<Eigen::Lower>().rankUpdate(Jw.transpose());
    H.triangularView<Eigen::StrictlyUpper>() = H.transpose();
    const Eigen::VectorXd g = Jw.transpose() * rw;
    const double rr = rw.squaredNorm(), wsum = d.w.sum();
    // lambda's unit: trace of the data term's weight block over trace(G), fixed at the start.
    if (hscale_ < 0) hscale_ = H.bottomRightCorner(m_, m_).trace() / std::max(basis_.G.trace(), 1e-300);
    Eigen::MatrixXd A = H;
    Eigen::VectorXd rhs = -g;
    const double s_data = std::max(d.sigma, o_.noise_mm);
    if (!lms_.empty()) add_landmark_terms(s_data, d.centre, A, rhs);
    if (np_) {
      H_pose_ = H.topLeftCorner(6, 6);
      centre_pose_ = d.centre;
      scale_pose_ = s_data;
    }
    // MAP: the pose prior weighted by the data's scale squared (as the landmark term).
    if (np_ && o_.pose_prior) add_pose_prior(*o_.pose_prior, D_, d.centre, s_data * s_data, A.topLeftCorner(6, 6), rhs.head(6));
    for (int j : support_modes_) {
      const double ws = s_data * s_data / (o_.support_sigma_mm * o_.support_sigma_mm);
      A(np_ + j, np_ + j) += ws;
      rhs[np_ + j] -= ws * alpha_[j];
    }
    A.bottomRightCorner(m_, m_) += lambda * hscale_ * basis_.G;
    A.diagonal().array() += 1e-10 * A.diagonal().maxCoeff();
    rhs.tail(m_) -= lambda * hscale_ * (basis_.G * alpha_);
    Eigen::VectorXd delta = A.ldlt().solve(rhs);
    if (!delta.allFinite()) {
      stop_ = "numerical failure";
      return false;
    }
    rec.rms_mm = pr.rms;
    rec.predicted_rms_mm = std::sqrt(std::max(0.0, rr + 2.0 * g.dot(delta) + delta.dot(H * delta)) / wsum);
    rec.lambda = lambda;
    rec.points_used = static_cast<int>(pr.kept.size());
    apply_step(delta, d.centre, q, rec);
    return true;
  }

  // Damped step: a weight step that reverses the previous one (in the energy metric) is an
  // oscillation between two sets of correspondences: the step factor is halved.
  void apply_step(Eigen::VectorXd delta, const Eigen::Vector3d& centre, const Eigen::Matrix3Xd& q, LoadFitIteration& rec) {
    if (prev_step_.size() == m_ && delta.tail(m_).dot(basis_.G * prev_step_) < 0) beta_ = std::max(0.125, 0.5 * beta_);
    else beta_ = std::min(1.0, 2.0 * beta_);
    delta *= beta_;
    prev_step_ = delta.tail(m_);
    if (np_) {
      const Eigen::Vector3d om = delta.head<3>();
      Eigen::Isometry3d step = Eigen::Isometry3d::Identity();
      if (om.norm() > 0) step.linear() = Eigen::AngleAxisd(om.norm(), om.normalized()).toRotationMatrix();
      step.translation() = centre - step.linear() * centre + delta.segment<3>(3);
      D_ = step * D_;
      rec.step_pose_mm = ((step * q) - q).colwise().norm().maxCoeff();
    }
    const Eigen::VectorXd da = delta.tail(m_);
    alpha_ += da;
    const int nv = mesh_.num_vertices();
    const Eigen::VectorXd du = basis_.U * da;
    rec.step_shape_mm = Eigen::Map<const Eigen::Matrix3Xd>(du.data(), 3, nv).colwise().norm().maxCoeff();
    const Eigen::VectorXd u = basis_.U * alpha_;
    x_ = rest_ + Eigen::Map<const Eigen::Matrix3Xd>(u.data(), 3, nv);
    rec.strain_energy = 0.5 * alpha_.dot(basis_.G * alpha_);
  }

  void accept(LoadFitResult& res) const {
    res.accepted = true;
    res.x_Model_mm = x_;
    res.D = D_;
    res.alpha = alpha_;
    res.max_displacement_mm = (x_ - rest_).colwise().norm().maxCoeff();
    res.strain_energy = 0.5 * alpha_.dot(basis_.G * alpha_);
    if (basis_.gravity > 0 && res.strain_energy > 0) {
      const int g0 = 3 * basis_.patches;
      const Eigen::VectorXd ag = alpha_.segment(g0, basis_.gravity);
      res.gravity_fraction = 0.5 * ag.dot(basis_.G.block(g0, g0, basis_.gravity, basis_.gravity) * ag) / res.strain_energy;
    }
    const SelfContactDetector check(rest_, mesh_.surface_tris);
    res.crossed_vertices = check.count_crossed(x_, 0.5 * check.exclusion_mm());
    res.landmark_final_rms_mm = landmark_rms(D_, alpha_);
    res.message = stop_;
  }

  const TetMesh& mesh_;
  const LoadBasis& basis_;
  const Eigen::Matrix3Xd& data_;
  const LoadFitOptions& o_;
  const Eigen::Matrix3Xd& rest_;
  const int m_, np_;       // basis modes; pose parameters (6, or 0 without estimate_pose)
  const double noise_;     // mm, at least 1e-6
  const double s_axis_;    // landmark error per coordinate, mm
  const bool map_prior_;   // the strain prior sets the regularisation (else the discrepancy principle)
  std::vector<LandmarkBinding> lms_;
  std::vector<int> support_modes_;
  double rigid_chi_ = 0.0;
  Eigen::VectorXd alpha_;
  Eigen::Isometry3d D_ = Eigen::Isometry3d::Identity();
  Eigen::Matrix3Xd x_;
  double hscale_ = -1.0;  // lambda's unit, fixed at the first iteration
  Eigen::VectorXd prev_step_;
  double beta_ = 1.0;
  int total_ = 0;  // iterations over all levels
  std::string stop_ = "schedule completed";
  Matrix6d H_pose_ = Matrix6d::Zero();  // the data's pose information at the last step
  Eigen::Vector3d centre_pose_ = Eigen::Vector3d::Zero();
  double scale_pose_ = 0.0;
};

}  // namespace

LoadFitResult fit_load_basis(const Scene& scene, const LoadBasis& basis, const Eigen::Matrix3Xd& data, const std::vector<LandmarkPair>& landmarks,
                             const LoadFitOptions& o) {
  const auto t0 = Clock::now();
  const TetMesh& mesh = scene.problem.mesh;
  const int nv = mesh.num_vertices();
  if (basis.U.rows() != 3 * nv) throw std::invalid_argument("load basis: built for another mesh (" + std::to_string(basis.U.rows() / 3) + " vertices, scene has " + std::to_string(nv) + ")");
  LoadFitResult res;
  res.x_Model_mm = mesh.rest_positions_World_mm;
  res.alpha = Eigen::VectorXd::Zero(basis.modes());
  LoadFit fit(mesh, basis, data, landmarks, o);
  res.landmarks_used = fit.landmarks();
  res.landmark_rigid_rms_mm = res.landmark_final_rms_mm = fit.landmark_rms(Eigen::Isometry3d::Identity(), res.alpha);
  if (std::string why = fit.rigid_fit_suffices(res); !why.empty()) {
    res.message = std::move(why);
    res.wall_time_s = seconds_since(t0);
    return res;
  }
  res.objective_rigid = fit.objective(Eigen::Isometry3d::Identity(), res.alpha, mesh.rest_positions_World_mm);
  fit.run_schedule(t0, res);
  fit.conclude(t0, res);
  return res;
}

}  // namespace arnav::host
