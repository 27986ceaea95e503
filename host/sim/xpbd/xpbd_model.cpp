#include "host/sim/xpbd/xpbd_model.hpp"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <chrono>
#include <omp.h>
#include <cmath>
#include <stdexcept>
#include <string>

#include "host/sim/model_setup.hpp"
#include "host/sim/element_measure.hpp"
#include "host/sim/rotation_extraction.hpp"
#include "host/sim/step_health.hpp"
#include "host/sim/tet_geometry.hpp"

namespace arnav::host {

namespace {

// cof(F) = d det(F) / dF: column k is the cross product of the other two columns.
inline Eigen::Matrix3d cofactor(const Eigen::Matrix3d& F) {
  Eigen::Matrix3d c;
  c.col(0) = F.col(1).cross(F.col(2));
  c.col(1) = F.col(2).cross(F.col(0));
  c.col(2) = F.col(0).cross(F.col(1));
  return c;
}

// Tets inverted for longer than this (simulated time) are beyond recovery.
constexpr double kInversionGrace_s = 1.0;
// Rotation refinements per tet solve (warm-started from the last solve of the same tet).
constexpr int kRotationRefinements = 1;
// RMS constraint residual (strain units) above which the step is reported as not converged.
constexpr double kUnconvergedResidual = 0.01;

}  // namespace

XpbdModel::XpbdModel(const SimProblem& problem, const ModelConfig& config) : config_(config) {
  check_iterative_config(config, "xpbd");
  const TetMesh& mesh = problem.mesh;
  mass_ = checked_masses_kg(problem, "xpbd");
  const int n = mesh.num_vertices();
  gravity_ = problem.gravity_World_mm_s2;
  vessels_ignored_ = problem.vessels.has_value() && !problem.vessels->segments.empty();
  x_ = mesh.rest_positions_World_mm;
  v_ = Eigen::Matrix3Xd::Zero(3, n);
  x_prev_ = x_;

  if (config.energy == "neo_hookean") {
    neo_hookean_ = true;
    // Its shear stiffness at rest lives in the multiplier of C_D = |F| (a prestress that
    // the gradient's rotation turns into shear force). XPBD's later sweeps ignore how the
    // gradient of an already loaded constraint changes, so a second sweep per substep
    // finds no shear stiffness and round-off grows without bound (measured: a box at rest
    // drifted 5e-3 mm in 3 steps of 2 sweeps). One sweep per substep is stable.
    if (config.iterations != 1)
      throw std::invalid_argument("xpbd: energy neo_hookean needs iterations = 1 (got " + std::to_string(config.iterations) +
                                  "): raise substeps instead (small steps), or use energy corotated");
  } else if (config.energy.empty() || config.energy == "corotated") {
    neo_hookean_ = false;
  } else {
    throw std::invalid_argument("xpbd: unknown energy '" + config.energy + "': use corotated or neo_hookean");
  }
  coloring_ = greedy_vertex_coloring(mesh.tets, n);
  original_index_ = coloring_.order;
  mass_damping_per_s_ = Eigen::VectorXd::Zero(n);
  if (neo_hookean_) {
    build_neo_hookean_batches(problem);
    mass_damping_per_s_ = mass_damping_per_s_.cwiseQuotient(mass_);
    set_fixed_vertices(problem.fixed_vertices);
    reset_ledger();
    return;
  }
  tets_.resize(mesh.tets.size());
  for (std::size_t k = 0; k < coloring_.order.size(); ++k) {
    const int t = coloring_.order[k];
    const int region = mesh.tet_region.empty() ? 0 : mesh.tet_region[t];
    const Material& mat = problem.region_materials[region];
    const Lame lame = lame_from(mat);
    TetData& d = tets_[k];
    d.v = mesh.tets[t];
    d.Dm_inv = edge_matrix(x_, d.v).inverse();
    d.volume_mm3 = signed_volume_mm3(x_, d.v);
    d.mu_kPa = lame.mu_kPa;
    d.lambda_kPa = lame.lambda_kPa;
    d.beta_s = mat.damping_stiffness_s;
    for (int v : d.v) mass_damping_per_s_[v] += 0.25 * d.volume_mm3 * mat.density_kg_per_mm3 * mat.damping_mass_per_s;
  }
  mass_damping_per_s_ = mass_damping_per_s_.cwiseQuotient(mass_);
  lambda_dev_.assign(tets_.size(), Eigen::Matrix3d::Zero());
  lambda_vol_.assign(tets_.size(), 0.0);
  rotation_.assign(tets_.size(), Eigen::Quaterniond::Identity());
  set_fixed_vertices(problem.fixed_vertices);
  reset_ledger();
}

void XpbdModel::build_neo_hookean_batches(const SimProblem& problem) {
  const TetMesh& mesh = problem.mesh;
  using xpbd::kLanes;
  const int n = mesh.num_vertices(), nt = mesh.num_tets();
  // Two halves split at the median tet centroid along the longest axis of the body; a
  // tet whose vertices are all touched only by tets of its own half is interior to it,
  // every other tet belongs to the interface. The halves share no vertex, so two threads
  // sweep them at the same time without colours or barriers; the interface (a thin layer
  // along the cut) follows on one thread. The split does not depend on the thread count,
  // so 1 and 2 threads compute the same positions.
  std::vector<Eigen::Vector3d> centroid(static_cast<std::size_t>(nt), Eigen::Vector3d::Zero());
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(HUGE_VAL), hi = -lo;
  for (int t = 0; t < nt; ++t) {
    Eigen::Vector3d& c = centroid[static_cast<std::size_t>(t)];
    for (int v : mesh.tets[t]) c += 0.25 * x_.col(v);
    lo = lo.cwiseMin(c);
    hi = hi.cwiseMax(c);
  }
  const Eigen::Vector3d extent = hi - lo;
  const int axis = extent.x() >= extent.y() && extent.x() >= extent.z() ? 0 : (extent.y() >= extent.z() ? 1 : 2);
  std::vector<double> key(static_cast<std::size_t>(nt));
  for (int t = 0; t < nt; ++t) key[static_cast<std::size_t>(t)] = centroid[static_cast<std::size_t>(t)][axis];
  std::vector<double> sorted = key;
  std::nth_element(sorted.begin(), sorted.begin() + nt / 2, sorted.end());
  const double cut = sorted[static_cast<std::size_t>(nt / 2)];
  std::vector<unsigned char> half(static_cast<std::size_t>(nt)), touched(static_cast<std::size_t>(n), 0);
  for (int t = 0; t < nt; ++t) {
    half[static_cast<std::size_t>(t)] = key[static_cast<std::size_t>(t)] < cut ? 0 : 1;
    for (int v : mesh.tets[t]) touched[static_cast<std::size_t>(v)] |= static_cast<unsigned char>(1u << half[static_cast<std::size_t>(t)]);
  }
  std::array<std::vector<std::array<int, 4>>, 3> group_tets;
  std::array<std::vector<int>, 3> group_index;
  for (int t = 0; t < nt; ++t) {
    int g = half[static_cast<std::size_t>(t)];
    for (int v : mesh.tets[t])
      if (touched[static_cast<std::size_t>(v)] == 3) g = 2;
    group_tets[static_cast<std::size_t>(g)].push_back(mesh.tets[t]);
    group_index[static_cast<std::size_t>(g)].push_back(t);
  }
  for (auto& list : nh_vertices_) list.clear();
  for (int v = 0; v < n; ++v) nh_vertices_[static_cast<std::size_t>(touched[static_cast<std::size_t>(v)] - 1)].push_back(v);

  // Within a group, colours only make batches: the 8 tets of a batch touch distinct
  // vertices (one thread runs a group's batches in order, Gauss-Seidel between them).
  xpbd::NhBatches& nb = nh_;
  nb.batches.clear();
  nb.count.clear();
  nb.tet.clear();
  nb.group_begin[0] = 0;
  for (std::size_t g = 0; g < 3; ++g) {
    const Coloring col = greedy_vertex_coloring(group_tets[g], n);
    for (int c = 0; c < col.num_colors(); ++c) {
      for (int k = col.color_offsets[c]; k < col.color_offsets[c + 1]; ++k) {
        const int slot = k - col.color_offsets[c], l = slot % kLanes;
        if (l == 0) {
          nb.batches.emplace_back();
          nb.count.push_back(0);
          nb.tet.insert(nb.tet.end(), kLanes, -1);
        }
        const std::size_t bi = nb.batches.size() - 1;
        const int t = group_index[g][static_cast<std::size_t>(col.order[static_cast<std::size_t>(k)])];
        nb.tet[bi * kLanes + static_cast<std::size_t>(l)] = t;
        nb.count[bi] = l + 1;
        const int region = mesh.tet_region.empty() ? 0 : mesh.tet_region[t];
        const Material& mat = problem.region_materials[region];
        const Lame lame = lame_from(mat);
        // Stable Neo-Hookean linearises to Lame (mu, lambda - mu): shift lambda by mu so
        // that small strains see the region's E and nu.
        const double mu = lame.mu_kPa, lambda = lame.lambda_kPa + lame.mu_kPa;
        const double V = signed_volume_mm3(x_, mesh.tets[t]);
        const Eigen::Matrix3d Dm_inv = edge_matrix(x_, mesh.tets[t]).inverse();
        xpbd::NhBatch& b = nb.batches[bi];
        for (int a = 0; a < 4; ++a) b.v[a][l] = mesh.tets[t][a];
        for (int a = 0; a < 3; ++a)
          for (int j = 0; j < 3; ++j) b.b[a][j][l] = Dm_inv(a, j);
        b.inv_mu_V[l] = 1.0 / (mu * V);
        b.inv_lambda_V[l] = 1.0 / (lambda * V);
        b.gamma[l] = 1.0 + mu / lambda;
        b.beta_s[l] = mat.damping_stiffness_s;
        b.mu_V[l] = mu * V;
        b.lambda_V[l] = lambda * V;
        if (mat.damping_stiffness_s != 0.0) nh_damped_ = true;
        for (int v : mesh.tets[t]) mass_damping_per_s_[v] += 0.25 * V * mat.density_kg_per_mm3 * mat.damping_mass_per_s;
      }
    }
    nb.group_begin[g + 1] = static_cast<int>(nb.batches.size());
  }
  // Unused lanes repeat lane 0 (finite arithmetic; never written back nor summed).
  for (std::size_t bi = 0; bi < nb.batches.size(); ++bi) {
    xpbd::NhBatch& b = nb.batches[bi];
    for (int l = nb.count[bi]; l < kLanes; ++l) {
      for (int a = 0; a < 4; ++a) b.v[a][l] = b.v[a][0];
      for (int a = 0; a < 3; ++a)
        for (int j = 0; j < 3; ++j) b.b[a][j][l] = b.b[a][j][0];
      b.inv_mu_V[l] = b.inv_mu_V[0];
      b.inv_lambda_V[l] = b.inv_lambda_V[0];
      b.gamma[l] = b.gamma[0];
      b.beta_s[l] = b.beta_s[0];
      b.mu_V[l] = b.mu_V[0];
      b.lambda_V[l] = b.lambda_V[0];
    }
  }
}

std::array<int, 3> XpbdModel::neo_hookean_group_tets() const {
  std::array<int, 3> out{};
  for (std::size_t g = 0; g < 3; ++g)
    for (int bi = nh_.group_begin[g]; bi < nh_.group_begin[g + 1]; ++bi) out[g] += nh_.count[static_cast<std::size_t>(bi)];
  return out;
}

void XpbdModel::update_tet_mass_blocks() {
  for (xpbd::NhBatch& b : nh_.batches) {
    for (int l = 0; l < xpbd::kLanes; ++l) {
      Eigen::Matrix3d B = Eigen::Matrix3d::Zero();
      Eigen::Vector3d b0 = Eigen::Vector3d::Zero();
      for (int a = 1; a < 4; ++a) {
        const Eigen::Vector3d ba(b.b[a - 1][0][l], b.b[a - 1][1][l], b.b[a - 1][2][l]);
        B += inv_mass_[b.v[a][l]] * ba * ba.transpose();
        b0 -= ba;
      }
      B += inv_mass_[b.v[0][l]] * b0 * b0.transpose();
      b.B[0][l] = B(0, 0);
      b.B[1][l] = B(0, 1);
      b.B[2][l] = B(0, 2);
      b.B[3][l] = B(1, 1);
      b.B[4][l] = B(1, 2);
      b.B[5][l] = B(2, 2);
    }
  }
  for (TetData& d : tets_) {
    const Eigen::Vector3d b0 = -d.Dm_inv.colwise().sum().transpose();
    d.B = inv_mass_[d.v[0]] * b0 * b0.transpose();
    for (int a = 1; a < 4; ++a) {
      const Eigen::Vector3d b = d.Dm_inv.row(a - 1).transpose();
      d.B += inv_mass_[d.v[a]] * b * b.transpose();
    }
  }
}

void XpbdModel::reset_rotations() {
  for (std::size_t k = 0; k < tets_.size(); ++k) {
    const Eigen::Matrix3d F = edge_matrix(x_, tets_[k].v) * tets_[k].Dm_inv;
    rotation_[k] = F.allFinite() ? Eigen::Quaterniond(polar_rotation(F)) : Eigen::Quaterniond::Identity();
  }
}

void XpbdModel::set_fixed_vertices(const std::vector<int>& vertices) {
  check_vertex_indices(vertices, static_cast<int>(x_.cols()), "set_fixed_vertices");
  fixed_.assign(static_cast<std::size_t>(x_.cols()), 0);
  inv_mass_ = mass_.cwiseInverse();
  for (int v : vertices) {
    fixed_[static_cast<std::size_t>(v)] = 1;
    inv_mass_[v] = 0.0;
    v_.col(v).setZero();
  }
  update_tet_mass_blocks();
}

AttachmentId XpbdModel::add_attachment(const AttachmentSpec& spec) {
  double work = 0.0;
  const AttachmentId id = attachments_.add(spec, x_, work);
  ledger_.add_work(work);
  return id;
}
void XpbdModel::set_attachment_target(AttachmentId id, const Eigen::Vector3d& target_World_mm) {
  ledger_.add_work(attachments_.set_target(id, target_World_mm, x_));
}
void XpbdModel::set_attachment_stiffness(AttachmentId id, double stiffness_mN_per_mm) {
  ledger_.add_work(attachments_.set_stiffness(id, stiffness_mN_per_mm, x_));
}
void XpbdModel::remove_attachment(AttachmentId id) { ledger_.add_work(attachments_.remove(id, x_)); }

void XpbdModel::reset_ledger() {
  ledger_.reset(kinetic_energy(mass_, v_) + elastic_energy(), gravity_potential(mass_, x_, gravity_));
}

void XpbdModel::set_state(const Eigen::Matrix3Xd& positions_World_mm, const Eigen::Matrix3Xd& velocities_World_mm_s) {
  check_state_shape(positions_World_mm, velocities_World_mm_s, static_cast<int>(x_.cols()));
  x_ = positions_World_mm;
  v_ = velocities_World_mm_s;
  for (std::size_t i = 0; i < fixed_.size(); ++i)
    if (fixed_[i]) v_.col(static_cast<Eigen::Index>(i)).setZero();
  inverted_time_s_ = 0.0;
  inverted_at_end_ = -1;
  reset_rotations();
  reset_ledger();
}

double XpbdModel::solve_tets(double h) {
  double residual_sq = 0.0;
  double* X = x_.data();
  const double* XP = x_prev_.data();
  const double* W = inv_mass_.data();
  const int threads = config_.threads;
  const int colors = coloring_.num_colors();
  const double inv_h2 = 1.0 / (h * h);
#pragma omp parallel num_threads(threads) if (threads > 1) reduction(+ : residual_sq)
  for (int c = 0; c < colors; ++c) {
#pragma omp for schedule(static)
    for (int k = coloring_.color_offsets[c]; k < coloring_.color_offsets[c + 1]; ++k) {
      const std::size_t ks = static_cast<std::size_t>(k);
      const TetData& d = tets_[ks];
      Eigen::Vector3d p[4], dx[4];
      double w[4];
      Eigen::Vector3d b[4];
      for (int a = 0; a < 4; ++a) {
        const int i = d.v[a];
        p[a] = Eigen::Vector3d(X[3 * i], X[3 * i + 1], X[3 * i + 2]);
        dx[a] = p[a] - Eigen::Vector3d(XP[3 * i], XP[3 * i + 1], XP[3 * i + 2]);
        w[a] = W[i];
      }
      b[1] = d.Dm_inv.row(0).transpose();
      b[2] = d.Dm_inv.row(1).transpose();
      b[3] = d.Dm_inv.row(2).transpose();
      b[0] = -(b[1] + b[2] + b[3]);
      Eigen::Matrix3d Ds;
      Ds << p[1] - p[0], p[2] - p[0], p[3] - p[0];
      Eigen::Matrix3d F = Ds * d.Dm_inv;
      const double damp = d.beta_s / h;  // XPBD damping gamma for Rayleigh beta
      // Rate of F over this substep, for the damping term grad C . (x - x_prev); skipped
      // (it is multiplied by zero) for undamped materials, the common case.
      Eigen::Matrix3d dF = Eigen::Matrix3d::Zero();
      if (damp != 0.0)
        dF = dx[0] * b[0].transpose() + dx[1] * b[1].transpose() + dx[2] * b[2].transpose() + dx[3] * b[3].transpose();

      // Deviatoric block: C = F - R, dC_ij/dx_a = b_a[j] e_i, so the system is
      // dLambda ((1 + damp) B + alpha I) = -(C + alpha Lambda) - damp dF (row by row).
      // Warm-started: R keeps converging over sweeps and substeps, so one refinement per
      // solve suffices (docs/benchmarks.md: a second one changed the benchmark's final
      // positions by less than the solver's own error, at 15 % more work per sweep).
      const Eigen::Matrix3d R = refine_rotation(F, rotation_[ks], kRotationRefinements, 1e-9);
      const double alpha_dev = inv_h2 / (2.0 * d.mu_kPa * d.volume_mm3);
      Eigen::Matrix3d& lam = lambda_dev_[ks];
      const Eigen::Matrix3d r_dev = -(F - R) - alpha_dev * lam;
      residual_sq += r_dev.squaredNorm();
      const Eigen::Matrix3d A = (1.0 + damp) * d.B + alpha_dev * Eigen::Matrix3d::Identity();
      const Eigen::Matrix3d dlam = (damp != 0.0 ? Eigen::Matrix3d(r_dev - damp * dF) : r_dev) * A.inverse();  // A symmetric
      lam += dlam;
      for (int a = 0; a < 4; ++a) p[a] += w[a] * (dlam * b[a]);
      F += dlam * d.B;  // F after the deviatoric update (dF = sum_a w_a dlam b_a b_a^T)

      // Hydrostatic block: C_H = det F - 1, dC_H/dx_a = cof(F) b_a (absent for nu = 0).
      const double J = F.determinant();
      if (d.lambda_kPa <= 0.0) {
        for (int a = 0; a < 4; ++a) {
          if (w[a] == 0.0) continue;
          const int i = d.v[a];
          X[3 * i] = p[a].x();
          X[3 * i + 1] = p[a].y();
          X[3 * i + 2] = p[a].z();
        }
        continue;
      }
      const Eigen::Matrix3d cof = cofactor(F);
      const double alpha_vol = inv_h2 / (d.lambda_kPa * d.volume_mm3);
      double a_vol = 0.0, rate = 0.0;
      Eigen::Vector3d g[4];
      for (int a = 0; a < 4; ++a) {
        g[a] = cof * b[a];
        a_vol += w[a] * g[a].squaredNorm();
        if (damp != 0.0) rate += g[a].dot(dx[a]);
      }
      const double r_vol = -(J - 1.0) - alpha_vol * lambda_vol_[ks];
      residual_sq += r_vol * r_vol;
      const double denom = (1.0 + damp) * a_vol + alpha_vol;
      if (denom > 0.0 && std::isfinite(denom)) {
        const double dl = (damp != 0.0 ? r_vol - damp * rate : r_vol) / denom;
        lambda_vol_[ks] += dl;
        for (int a = 0; a < 4; ++a) p[a] += w[a] * dl * g[a];
      }
      for (int a = 0; a < 4; ++a) {
        if (w[a] == 0.0) continue;
        const int i = d.v[a];
        X[3 * i] = p[a].x();
        X[3 * i + 1] = p[a].y();
        X[3 * i + 2] = p[a].z();
      }
    }
  }
  return residual_sq;
}

void XpbdModel::step_neo_hookean(double h, StepSummary& summary, bool& converged, double& energy, int& inverted) {
  // At most two threads: one per half of the mesh (build_neo_hookean_batches).
  const int threads = std::min(config_.threads, 2);
  const double tets = static_cast<double>(coloring_.order.size());
  const std::array<int, 4> group = nh_.group_begin;
  xpbd::SweepParams params;
  params.h_s = h;
  params.damped = nh_damped_;
  double* X = x_.data();
  double* V = v_.data();
  double* XP = x_prev_.data();
  const double* W = inv_mass_.data();
  const double* mass_damping = mass_damping_per_s_.data();
  const xpbd::NhBatch* batches = nh_.batches.data();
  const int* count = nh_.count.data();
  const Eigen::Vector3d g = gravity_;
  // Per-thread partial sums, a cache line apart.
  std::array<double, 16> partial{};
  std::array<int, 32> partial_inverted{};
  bool stop = false;
  // One parallel region for the whole step. Thread d owns half d: it moves the vertices
  // only half d touches (prediction, sweep, velocity) with no synchronisation; thread 0
  // also owns the vertices on the cut and sweeps the interface and the attachments while
  // the other waits. Two barriers per sweep.
#pragma omp parallel num_threads(threads) if (threads > 1)
  {
    const int tid = omp_get_thread_num(), nt = omp_get_num_threads();
    auto predict = [&](const std::vector<int>& vertices) {
      for (int i : vertices) {
        for (int k = 0; k < 3; ++k) XP[3 * i + k] = X[3 * i + k];
        if (fixed_[static_cast<std::size_t>(i)]) continue;
        // Damp the carried velocity only: damping gravity's increment too would weaken
        // gravity at steady state by 1/(1 + h alpha).
        const double keep = 1.0 / (1.0 + h * mass_damping[i]);
        for (int k = 0; k < 3; ++k) {
          V[3 * i + k] = V[3 * i + k] * keep + h * g[k];
          X[3 * i + k] += h * V[3 * i + k];
        }
      }
    };
    auto update_velocity = [&](const std::vector<int>& vertices) {
      for (int i : vertices)
        for (int k = 0; k < 3; ++k) V[3 * i + k] = (X[3 * i + k] - XP[3 * i + k]) / h;
    };
    for (int s = 0; s < config_.substeps && !stop; ++s) {
      for (int d = tid; d < 2; d += nt) predict(nh_vertices_[static_cast<std::size_t>(d)]);
      if (tid == 0) predict(nh_vertices_[2]);
      for (int it = 0; it < config_.iterations; ++it) {
        double correction = 0.0;
        for (int d = tid; d < 2; d += nt)
          correction += xpbd::solve_nh_batches(batches, count, group[static_cast<std::size_t>(d)],
                                               group[static_cast<std::size_t>(d) + 1], X, XP, W, params);
        partial[static_cast<std::size_t>(8 * tid)] = correction;
#pragma omp barrier
        if (tid == 0) {
          double sum = xpbd::solve_nh_batches(batches, count, group[2], group[3], X, XP, W, params);
          if (it == 0)
            for (int id : attachments_.active()) attachments_[id].lambda.setZero();
          solve_attachments(h);
          for (int t = 0; t < nt; ++t) sum += partial[static_cast<std::size_t>(8 * t)];
          const double rms = std::sqrt(sum / tets);
          ++summary.iterations;
          if (s == 0 && it == 0) summary.initial_residual = rms;
          summary.final_residual = rms;
          if (config_.tolerance > 0.0 && rms < config_.tolerance) {
            converged = true;
            stop = true;
          }
        }
#pragma omp barrier
        if (stop) break;
      }
      for (int d = tid; d < 2; d += nt) update_velocity(nh_vertices_[static_cast<std::size_t>(d)]);
      if (tid == 0) update_velocity(nh_vertices_[2]);
    }
#pragma omp barrier
    // Energy and inverted tets at the end of the step, in the same region.
    const int num_batches = group[3];
    const int b0 = static_cast<int>(static_cast<long>(num_batches) * tid / nt);
    const int b1 = static_cast<int>(static_cast<long>(num_batches) * (tid + 1) / nt);
    int bad = 0;
    partial[static_cast<std::size_t>(8 * tid)] = xpbd::nh_energy(batches, count, b0, b1, X, &bad);
    partial_inverted[static_cast<std::size_t>(16 * tid)] = bad;
  }
  energy = attachments_.energy(x_);
  inverted = 0;
  for (int t = 0; t < threads; ++t) {
    energy += partial[static_cast<std::size_t>(8 * t)];
    inverted += partial_inverted[static_cast<std::size_t>(16 * t)];
  }
}

void XpbdModel::solve_attachments(double h) {
  for (int id : attachments_.active()) {
    Attachment& a = attachments_[id];
    const double alpha = 1.0 / (a.stiffness_mN_per_mm * h * h);
    double denom = alpha;
    for (int k = 0; k < a.count; ++k) denom += a.weights[k] * a.weights[k] * inv_mass_[a.vertices[k]];
    const Eigen::Vector3d C = a.point(x_) - a.target_World_mm;
    const Eigen::Vector3d dl = -(C + alpha * a.lambda) / denom;
    a.lambda += dl;
    for (int k = 0; k < a.count; ++k) x_.col(a.vertices[k]) += inv_mass_[a.vertices[k]] * a.weights[k] * dl;
  }
}

StepSummary XpbdModel::step(double dt_s) {
  check_dt(dt_s);
  const auto start = std::chrono::steady_clock::now();
  StepSummary summary;
  summary.termination = "max_iterations";
  const double h = dt_s / config_.substeps;
  const int n = static_cast<int>(x_.cols());
  const int threads = config_.threads;
  const double constraints = 10.0 * static_cast<double>(tets_.size());
  // The count at the end of the last step still holds unless set_state moved the vertices.
  const int inverted_at_start = inverted_at_end_ >= 0 ? inverted_at_end_ : count_inverted();
  bool converged = false;
  double energy = 0.0;
  int inverted = 0;
  if (neo_hookean_) step_neo_hookean(h, summary, converged, energy, inverted);
  for (int s = 0; s < (neo_hookean_ ? 0 : config_.substeps); ++s) {
#pragma omp parallel for num_threads(threads) if (threads > 1) schedule(static)
    for (int i = 0; i < n; ++i) {
      x_prev_.col(i) = x_.col(i);
      if (fixed_[static_cast<std::size_t>(i)]) continue;
      // Damp the carried velocity only: damping gravity's increment too would weaken
      // gravity at steady state by 1/(1 + h alpha).
      v_.col(i) = v_.col(i) / (1.0 + h * mass_damping_per_s_[i]) + h * gravity_;
      x_.col(i) += h * v_.col(i);
    }
    for (auto& l : lambda_dev_) l.setZero();
    std::fill(lambda_vol_.begin(), lambda_vol_.end(), 0.0);
    for (int id : attachments_.active()) attachments_[id].lambda.setZero();
    for (int it = 0; it < config_.iterations; ++it) {
      const double rms = std::sqrt(solve_tets(h) / constraints);
      solve_attachments(h);
      ++summary.iterations;
      if (s == 0 && it == 0) summary.initial_residual = rms;
      summary.final_residual = rms;
      if (config_.tolerance > 0.0 && rms < config_.tolerance) {
        converged = true;
        break;
      }
    }
#pragma omp parallel for num_threads(threads) if (threads > 1) schedule(static)
    for (int i = 0; i < n; ++i) v_.col(i) = (x_.col(i) - x_prev_.col(i)) / h;
  }
  if (converged) summary.termination = "converged";
  if (vessels_ignored_) {
    report(summary, "vessel tree ignored: this model has no beam coupling (model vessels as a stiff tet region, or use corotational_fem)", false);
  }
  check_state(x_, v_, summary);
  if (!neo_hookean_) {
    inverted = count_inverted();
    energy = elastic_energy();
  }
  inverted_at_end_ = inverted;
  if (inverted > 0) {
    inverted_time_s_ += dt_s;
    const bool stuck = inverted_time_s_ > kInversionGrace_s;
    report(summary,
           "inverted tets: " + std::to_string(inverted) +
               (stuck ? " for more than " + std::to_string(kInversionGrace_s) + " s (beyond recovery)" : " (recovering)"),
           stuck);
  } else {
    inverted_time_s_ = 0.0;
    if (inverted_at_start > 0) report(summary, "inverted tets: " + std::to_string(inverted_at_start) + " at step start, recovered", false);
  }
  if (summary.final_residual > kUnconvergedResidual) {
    report(summary,
           std::string(neo_hookean_ ? "not converged: RMS strain correction of the last sweep " : "not converged: RMS constraint residual ") +
               std::to_string(summary.final_residual) +
               " (raise iterations or substeps; the tissue behaves softer than its material)",
           false);
  }
  summary.kinetic_energy = kinetic_energy(mass_, v_);
  summary.elastic_energy = energy;
  ledger_.check(summary.kinetic_energy + summary.elastic_energy, gravity_potential(mass_, x_, gravity_), summary);
  summary.wall_time_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

int XpbdModel::count_inverted() const {
  if (neo_hookean_) {
    int inverted = 0;
    xpbd::nh_energy(nh_.batches.data(), nh_.count.data(), 0, nh_.group_begin[3], x_.data(), &inverted);
    return inverted;
  }
  const int nt = static_cast<int>(tets_.size());
  const int threads = config_.threads;
  int count = 0;
#pragma omp parallel for num_threads(threads) if (threads > 1) reduction(+ : count) schedule(static)
  for (int k = 0; k < nt; ++k) {
    if (!(edge_matrix(x_, tets_[static_cast<std::size_t>(k)].v).determinant() > 0.0)) ++count;
  }
  return count;
}

double XpbdModel::elastic_energy() const {
  if (neo_hookean_) {
    int inverted = 0;
    return xpbd::nh_energy(nh_.batches.data(), nh_.count.data(), 0, nh_.group_begin[3], x_.data(), &inverted) +
           attachments_.energy(x_);
  }
  double e = 0.0;
  const int nt = static_cast<int>(tets_.size());
  const int threads = config_.threads;
#pragma omp parallel for num_threads(threads) if (threads > 1) reduction(+ : e) schedule(static)
  for (int k = 0; k < nt; ++k) {
    const TetData& d = tets_[static_cast<std::size_t>(k)];
    const Eigen::Matrix3d F = edge_matrix(x_, d.v) * d.Dm_inv;
    Eigen::Quaterniond q = rotation_[static_cast<std::size_t>(k)];
    const Eigen::Matrix3d R = refine_rotation(F, q, 1, 1e-6);  // R of the last sweep, one refinement
    const double J = F.determinant();
    e += d.volume_mm3 * (d.mu_kPa * (F - R).squaredNorm() + 0.5 * d.lambda_kPa * (J - 1.0) * (J - 1.0));
  }
  return e + attachments_.energy(x_);
}

std::vector<ElementMeasure> XpbdModel::element_measures() const {
  if (neo_hookean_) {
    std::vector<ElementMeasure> out(coloring_.order.size());
    for (std::size_t bi = 0; bi < nh_.batches.size(); ++bi) {
      const xpbd::NhBatch& b = nh_.batches[bi];
      for (int l = 0; l < nh_.count[bi]; ++l) {
        Eigen::Matrix3d Dm_inv;
        for (int a = 0; a < 3; ++a)
          for (int j = 0; j < 3; ++j) Dm_inv(a, j) = b.b[a][j][l];
        const Eigen::Matrix3d F = edge_matrix(x_, {b.v[0][l], b.v[1][l], b.v[2][l], b.v[3][l]}) * Dm_inv;
        const double J = F.determinant();
        // First Piola-Kirchhoff stress mu F + lambda (J - gamma) cof F (per unit volume:
        // mu_V / V = mu); Cauchy stress P F^T / J unless (nearly) inverted.
        const double V = 1.0 / (6.0 * Dm_inv.determinant());  // rest volume
        const double mu = b.mu_V[l] / V, lambda = b.lambda_V[l] / V;
        const Eigen::Matrix3d P = mu * F + lambda * (J - b.gamma[l]) * cofactor(F);
        const Eigen::Matrix3d sigma = J > 1e-6 ? Eigen::Matrix3d(P * F.transpose() / J) : P;
        out[static_cast<std::size_t>(nh_.tet[bi * xpbd::kLanes + static_cast<std::size_t>(l)])] = element_measure_from(F, sigma);
      }
    }
    return out;
  }
  std::vector<ElementMeasure> out(tets_.size());
  for (std::size_t k = 0; k < tets_.size(); ++k) {
    const TetData& d = tets_[k];
    const Eigen::Matrix3d F = edge_matrix(x_, d.v) * d.Dm_inv;
    const double J = F.determinant();
    // First Piola-Kirchhoff stress of the model's energy; Cauchy stress P F^T / J where
    // the element is not (nearly) inverted, else P itself as the best available measure.
    const Eigen::Matrix3d P = 2.0 * d.mu_kPa * (F - polar_rotation(F)) + d.lambda_kPa * (J - 1.0) * cofactor(F);
    const Eigen::Matrix3d sigma = J > 1e-6 ? Eigen::Matrix3d(P * F.transpose() / J) : P;
    out[static_cast<std::size_t>(original_index_[k])] = element_measure_from(F, sigma);
  }
  return out;
}

}  // namespace arnav::host
