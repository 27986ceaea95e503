// SIMD solve of the stable Neo-Hookean constraint blocks, kLanes tets at a time.
// The arithmetic is written on GCC/Clang vector types (one value per lane); the compiler
// lowers them to the widest registers the target has. The entry points are compiled for
// several instruction sets and picked at load time by the CPU (target_clones), so the
// default build still runs on any x86-64 while AVX2/AVX-512 machines get wide registers.
// This file is built with -fno-math-errno so that sqrt vectorises.
#include "host/sim/xpbd/neo_hookean_batches.hpp"

#include <cstring>

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(__SANITIZE_ADDRESS__)
#define ARNAV_XPBD_CLONES __attribute__((target_clones("default", "arch=x86-64-v3", "arch=x86-64-v4")))
#else
#define ARNAV_XPBD_CLONES
#endif

// Helpers are forced inline so that they are compiled into each target clone (a helper
// left out of line would be built for the baseline target only).
#define ARNAV_INLINE inline __attribute__((always_inline))

namespace arnav::host::xpbd {

namespace {

using vd = double __attribute__((vector_size(8 * kLanes)));

ARNAV_INLINE vd load(const double* p) {
  vd v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
ARNAV_INLINE vd vsqrt(vd x) {
  for (int l = 0; l < kLanes; ++l) x[l] = __builtin_sqrt(x[l]);
  return x;
}

// Vertex positions of the 4 corners of each lane's tet: p[a][i].
struct Corners {
  vd p[4][3];
};
ARNAV_INLINE Corners gather(const NhBatch& b, const double* X) {
  Corners c;
  for (int a = 0; a < 4; ++a)
    for (int l = 0; l < kLanes; ++l) {
      const double* x = X + 3 * static_cast<long>(b.v[a][l]);
      c.p[a][0][l] = x[0];
      c.p[a][1][l] = x[1];
      c.p[a][2][l] = x[2];
    }
  return c;
}

// F = sum_a p_a b_a^T = sum_{a=1..3} (p_a - p_0) b_a^T.
ARNAV_INLINE void deformation_gradient(const NhBatch& b, const Corners& c, vd F[3][3]) {
  vd bv[3][3];
  for (int a = 0; a < 3; ++a)
    for (int j = 0; j < 3; ++j) bv[a][j] = load(b.b[a][j]);
  for (int i = 0; i < 3; ++i) {
    const vd e1 = c.p[1][i] - c.p[0][i], e2 = c.p[2][i] - c.p[0][i], e3 = c.p[3][i] - c.p[0][i];
    for (int j = 0; j < 3; ++j) F[i][j] = e1 * bv[0][j] + e2 * bv[1][j] + e3 * bv[2][j];
  }
}

// cof(F) = d det F / dF (columns: cross products of the other two columns of F).
ARNAV_INLINE void cofactor(const vd F[3][3], vd C[3][3]) {
  C[0][0] = F[1][1] * F[2][2] - F[2][1] * F[1][2];
  C[1][0] = F[2][1] * F[0][2] - F[0][1] * F[2][2];
  C[2][0] = F[0][1] * F[1][2] - F[1][1] * F[0][2];
  C[0][1] = F[1][2] * F[2][0] - F[2][2] * F[1][0];
  C[1][1] = F[2][2] * F[0][0] - F[0][2] * F[2][0];
  C[2][1] = F[0][2] * F[1][0] - F[1][2] * F[0][0];
  C[0][2] = F[1][0] * F[2][1] - F[2][0] * F[1][1];
  C[1][2] = F[2][0] * F[0][1] - F[0][0] * F[2][1];
  C[2][2] = F[0][0] * F[1][1] - F[1][0] * F[0][1];
}

template <bool kDamped>
ARNAV_INLINE double solve_batch(const NhBatch& b, int count, double* X, const double* XP, const double* W, double h) {
  Corners c = gather(b, X);
  vd F[3][3], cof[3][3];
  deformation_gradient(b, c, F);
  cofactor(F, cof);
  const vd J = F[0][0] * cof[0][0] + F[1][0] * cof[1][0] + F[2][0] * cof[2][0];
  vd Ic = vd{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) Ic += F[i][j] * F[i][j];
  const vd norm_F = vsqrt(Ic);
  const vd inv_norm = 1.0 / norm_F;

  // Products with B = sum_a w_a b_a b_a^T give the block's Schur entries
  // grad C_k W grad C_l^T = tr(G_k B G_l^T) with G_D = F/|F|, G_H = cof F.
  const vd Bxx = load(b.B[0]), Bxy = load(b.B[1]), Bxz = load(b.B[2]), Byy = load(b.B[3]), Byz = load(b.B[4]),
           Bzz = load(b.B[5]);
  vd FB[3][3], CB[3][3];
  for (int i = 0; i < 3; ++i) {
    FB[i][0] = F[i][0] * Bxx + F[i][1] * Bxy + F[i][2] * Bxz;
    FB[i][1] = F[i][0] * Bxy + F[i][1] * Byy + F[i][2] * Byz;
    FB[i][2] = F[i][0] * Bxz + F[i][1] * Byz + F[i][2] * Bzz;
    CB[i][0] = cof[i][0] * Bxx + cof[i][1] * Bxy + cof[i][2] * Bxz;
    CB[i][1] = cof[i][0] * Bxy + cof[i][1] * Byy + cof[i][2] * Byz;
    CB[i][2] = cof[i][0] * Bxz + cof[i][1] * Byz + cof[i][2] * Bzz;
  }
  vd sFF = vd{}, sFC = vd{}, sCC = vd{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      sFF += FB[i][j] * F[i][j];
      sFC += FB[i][j] * cof[i][j];
      sCC += CB[i][j] * cof[i][j];
    }
  const double inv_h2 = 1.0 / (h * h);
  const vd alpha_d = load(b.inv_mu_V) * inv_h2, alpha_h = load(b.inv_lambda_V) * inv_h2;
  // Right side -(C + alpha lambda) with lambda = 0 (first and only sweep of the substep).
  vd r_d = -norm_F, r_h = load(b.gamma) - J;
  vd a11 = sFF * (inv_norm * inv_norm), a12 = sFC * inv_norm, a22 = sCC;
  if constexpr (kDamped) {
    // XPBD constraint damping with gamma = beta / h (Rayleigh beta): the rate term
    // grad C . (x - x_prev) enters the right side, (1 + gamma) scales the block.
    const vd damp = load(b.beta_s) * (1.0 / h);
    Corners prev = gather(b, XP);
    for (int a = 0; a < 4; ++a)
      for (int i = 0; i < 3; ++i) prev.p[a][i] = c.p[a][i] - prev.p[a][i];
    vd dF[3][3];
    deformation_gradient(b, prev, dF);
    vd rate_d = vd{}, rate_h = vd{};
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        rate_d += F[i][j] * dF[i][j];
        rate_h += cof[i][j] * dF[i][j];
      }
    r_d -= damp * rate_d * inv_norm;
    r_h -= damp * rate_h;
    const vd s = 1.0 + damp;
    a11 *= s;
    a12 *= s;
    a22 *= s;
  }
  a11 += alpha_d;
  a22 += alpha_h;
  // 2x2 solve; det >= alpha_d alpha_h > 0 (B is positive semi-definite).
  const vd inv_det = 1.0 / (a11 * a22 - a12 * a12);
  const vd dl_d = (a22 * r_d - a12 * r_h) * inv_det;
  const vd dl_h = (a11 * r_h - a12 * r_d) * inv_det;
  // Position update dx_a = w_a M b_a with M = dl_d F/|F| + dl_h cof F; the change of F
  // it makes is M B (for the residual).
  const vd md = dl_d * inv_norm;
  vd M[3][3];
  double correction = 0.0;
  vd dF2 = vd{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      M[i][j] = md * F[i][j] + dl_h * cof[i][j];
      const vd d = md * FB[i][j] + dl_h * CB[i][j];
      dF2 += d * d;
    }
  vd w[4];
  for (int a = 0; a < 4; ++a) {
    vd wa = vd{};
    for (int l = 0; l < kLanes; ++l) wa[l] = W[b.v[a][l]];
    w[a] = wa;
  }
  vd Mb[4][3];
  for (int i = 0; i < 3; ++i) Mb[0][i] = vd{};
  for (int a = 1; a < 4; ++a)
    for (int i = 0; i < 3; ++i) {
      Mb[a][i] = M[i][0] * load(b.b[a - 1][0]) + M[i][1] * load(b.b[a - 1][1]) + M[i][2] * load(b.b[a - 1][2]);
      Mb[0][i] -= Mb[a][i];
    }
  for (int a = 0; a < 4; ++a)
    for (int i = 0; i < 3; ++i) c.p[a][i] += w[a] * Mb[a][i];
  // Scatter the used lanes (the colour guarantees their vertices are distinct).
  for (int l = 0; l < count; ++l) {
    for (int a = 0; a < 4; ++a) {
      double* x = X + 3 * static_cast<long>(b.v[a][l]);
      x[0] = c.p[a][0][l];
      x[1] = c.p[a][1][l];
      x[2] = c.p[a][2][l];
    }
    correction += dF2[l];
  }
  return correction;
}

template <bool kDamped>
ARNAV_INLINE double solve_range(const NhBatch* batches, const int* count, int begin, int end, double* X, const double* XP,
                                const double* W, double h) {
  double sum = 0.0;
  for (int k = begin; k < end; ++k) sum += solve_batch<kDamped>(batches[k], count[k], X, XP, W, h);
  return sum;
}

}  // namespace

ARNAV_XPBD_CLONES
double solve_nh_batches(const NhBatch* batches, const int* count, int begin, int end, double* X, const double* XP,
                        const double* W, const SweepParams& params) {
  return params.damped ? solve_range<true>(batches, count, begin, end, X, XP, W, params.h_s)
                       : solve_range<false>(batches, count, begin, end, X, XP, W, params.h_s);
}

ARNAV_XPBD_CLONES
double nh_energy(const NhBatch* batches, const int* count, int begin, int end, const double* X, int* inverted) {
  double energy = 0.0;
  int bad = 0;
  for (int k = begin; k < end; ++k) {
    const NhBatch& b = batches[k];
    const Corners c = gather(b, X);
    vd F[3][3];
    deformation_gradient(b, c, F);
    const vd J = F[0][0] * (F[1][1] * F[2][2] - F[2][1] * F[1][2]) + F[1][0] * (F[2][1] * F[0][2] - F[0][1] * F[2][2]) +
                 F[2][0] * (F[0][1] * F[1][2] - F[1][1] * F[0][2]);
    vd Ic = vd{};
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) Ic += F[i][j] * F[i][j];
    const vd gamma = load(b.gamma), lambda_V = load(b.lambda_V);
    // Shifted so that rest stores zero: the constant lambda/2 (1 - gamma)^2 is removed.
    const vd e = 0.5 * load(b.mu_V) * (Ic - 3.0) + 0.5 * lambda_V * ((J - gamma) * (J - gamma) - (1.0 - gamma) * (1.0 - gamma));
    for (int l = 0; l < count[k]; ++l) {
      energy += e[l];
      if (!(J[l] > 0.0)) ++bad;
    }
  }
  *inverted += bad;
  return energy;
}

}  // namespace arnav::host::xpbd
