// SIMD solve of the stable Neo-Hookean constraint blocks, kLanes tets at a time.
// The arithmetic is written on GCC/Clang vector types (one value per lane); the compiler
// lowers them to the widest registers the target has. The entry points are compiled for
// several instruction sets and picked at load time by the CPU (target_clones), so the
// default build still runs on any x86-64 while AVX2/AVX-512 machines get wide registers.
// This file is built with -fno-math-errno so that sqrt vectorises.
#include "host/sim/xpbd/tet_batches.hpp"

#include <cstring>

// (Defined empty from the command line, the file builds for the compiler's target only:
// used to measure what each instruction set buys, docs/benchmarks.md.)
#ifndef ARNAV_XPBD_CLONES
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(__SANITIZE_ADDRESS__)
#define ARNAV_XPBD_CLONES __attribute__((target_clones("default", "arch=x86-64-v3", "arch=x86-64-v4")))
#else
#define ARNAV_XPBD_CLONES
#endif
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
ARNAV_INLINE Corners gather(const TetBatch& b, const double* X) {
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
ARNAV_INLINE void deformation_gradient(const TetBatch& b, const Corners& c, vd F[3][3]) {
  vd bv[3][3];
  for (int a = 0; a < 3; ++a)
    for (int j = 0; j < 3; ++j) bv[a][j] = load(b.b[a][j]);
  for (int i = 0; i < 3; ++i) {
    const vd e1 = c.p[1][i] - c.p[0][i], e2 = c.p[2][i] - c.p[0][i], e3 = c.p[3][i] - c.p[0][i];
    for (int j = 0; j < 3; ++j) F[i][j] = e1 * bv[0][j] + e2 * bv[1][j] + e3 * bv[2][j];
  }
}

// det F, expanded along the first column (the first column of cof(F) below).
ARNAV_INLINE vd determinant(const vd F[3][3]) {
  return F[0][0] * (F[1][1] * F[2][2] - F[2][1] * F[1][2]) + F[1][0] * (F[2][1] * F[0][2] - F[0][1] * F[2][2]) +
         F[2][0] * (F[0][1] * F[1][2] - F[1][1] * F[0][2]);
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

// dx_a = w_a M b_a (b_0 = -(b_1 + b_2 + b_3)) applied to the corners c, and the used
// lanes written back (the batch's tets touch distinct vertices).
ARNAV_INLINE void apply_update(const TetBatch& b, int count, double* X, const double* W, const vd M[3][3], Corners& c) {
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
  for (int l = 0; l < count; ++l)
    for (int a = 0; a < 4; ++a) {
      double* x = X + 3 * static_cast<long>(b.v[a][l]);
      x[0] = c.p[a][0][l];
      x[1] = c.p[a][1][l];
      x[2] = c.p[a][2][l];
    }
}

template <bool kDamped>
ARNAV_INLINE double solve_batch(const TetBatch& b, int count, double* X, const double* XP, const double* W, double h,
                                bool residual) {
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
  vd dF2 = vd{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      M[i][j] = md * F[i][j] + dl_h * cof[i][j];
      if (residual) {
        const vd d = md * FB[i][j] + dl_h * CB[i][j];
        dF2 += d * d;
      }
    }
  apply_update(b, count, X, W, M, c);
  double correction = 0.0;
  for (int l = 0; l < count; ++l) correction += dF2[l];
  return correction;
}

template <bool kDamped>
ARNAV_INLINE double solve_range(const TetBatch* batches, const int* count, const int* index, int num, double* X, const double* XP,
                                const double* W, double h, bool residual) {
  double sum = 0.0;
  for (int i = 0; i < num; ++i) {
    const int k = index[i];
    sum += solve_batch<kDamped>(batches[k], count[k], X, XP, W, h, residual);
  }
  return sum;
}

// Rotation matrix of unit quaternions (w, x, y, z per lane).
ARNAV_INLINE void quaternion_matrix(const vd q[4], vd R[3][3]) {
  const vd w = q[0], x = q[1], y = q[2], z = q[3];
  R[0][0] = 1.0 - 2.0 * (y * y + z * z);
  R[0][1] = 2.0 * (x * y - w * z);
  R[0][2] = 2.0 * (x * z + w * y);
  R[1][0] = 2.0 * (x * y + w * z);
  R[1][1] = 1.0 - 2.0 * (x * x + z * z);
  R[1][2] = 2.0 * (y * z - w * x);
  R[2][0] = 2.0 * (x * z - w * y);
  R[2][1] = 2.0 * (y * z + w * x);
  R[2][2] = 1.0 - 2.0 * (x * x + y * y);
}

// One step of the rotation extraction of Mueller et al. 2016 (as refine_rotation in
// rotation_extraction.hpp, warm-started from q): omega = sum_k r_k x f_k / |sum_k r_k . f_k|,
// q <- normalise((1, omega/2) q). Always the first-order quaternion (same axis, angle
// 2 atan(|omega|/2)): exact enough when warm, still a descent step when not, and free of
// branches across lanes. Updates q, returns R(q) in R.
ARNAV_INLINE void refine_rotation_lanes(const vd F[3][3], vd q[4], vd R[3][3]) {
  quaternion_matrix(q, R);
  vd ox = vd{}, oy = vd{}, oz = vd{}, dot = vd{};
  for (int k = 0; k < 3; ++k) {
    const vd rx = R[0][k], ry = R[1][k], rz = R[2][k], fx = F[0][k], fy = F[1][k], fz = F[2][k];
    ox += ry * fz - rz * fy;
    oy += rz * fx - rx * fz;
    oz += rx * fy - ry * fx;
    dot += rx * fx + ry * fy + rz * fz;
  }
  vd adot = dot;
  for (int l = 0; l < kLanes; ++l) adot[l] = __builtin_fabs(dot[l]);
  const vd half = 0.5 / (adot + 1e-9);
  ox *= half;
  oy *= half;
  oz *= half;
  // (1, o) * (w, v) = (w - o.v, w o + v + o x v)
  const vd w = q[0], x = q[1], y = q[2], z = q[3];
  vd nw = w - (ox * x + oy * y + oz * z);
  vd nx = x + w * ox + (oy * z - oz * y);
  vd ny = y + w * oy + (oz * x - ox * z);
  vd nz = z + w * oz + (ox * y - oy * x);
  const vd inv = 1.0 / vsqrt(nw * nw + nx * nx + ny * ny + nz * nz);
  q[0] = nw * inv;
  q[1] = nx * inv;
  q[2] = ny * inv;
  q[3] = nz * inv;
  quaternion_matrix(q, R);
}

// Fixed-corotated blocks of one batch, one after the other as in the scalar original:
// deviatoric C = F - R (R frozen; 9x9 block I3 (x) B, one 3x3 solve A = (1+g) B + alpha I)
// then hydrostatic C_H = det F - 1 on the F the first block left. rotation: 4 x kLanes
// (w, x, y, z), lambda: 10 x kLanes (9 deviatoric row-major, 1 hydrostatic).
template <bool kDamped, bool kMultipliers>
ARNAV_INLINE double solve_corotated_batch(const TetBatch& b, int count, double* X, const double* XP, const double* W,
                                          double* rotation, double* lambda, double h, bool residual) {
  Corners c = gather(b, X);
  vd F[3][3];
  deformation_gradient(b, c, F);
  vd q[4];
  for (int k = 0; k < 4; ++k) q[k] = load(rotation + k * kLanes);
  vd R[3][3];
  refine_rotation_lanes(F, q, R);
  for (int k = 0; k < 4; ++k) std::memcpy(rotation + k * kLanes, &q[k], sizeof(vd));

  const double inv_h2 = 1.0 / (h * h);
  const vd alpha_d = load(b.inv_mu_V) * inv_h2, alpha_h = load(b.inv_lambda_V) * inv_h2;
  const vd vol_on = load(b.gamma);  // corotated: 1 where the region has a volume term, 0 where lambda = 0
  vd damp = vd{}, dF[3][3];
  if constexpr (kDamped) {
    damp = load(b.beta_s) * (1.0 / h);
    Corners prev = gather(b, XP);
    for (int a = 0; a < 4; ++a)
      for (int i = 0; i < 3; ++i) prev.p[a][i] = c.p[a][i] - prev.p[a][i];
    deformation_gradient(b, prev, dF);
  }
  // Deviatoric: dLambda ((1 + g) B + alpha I) = -(F - R + alpha Lambda) - g dF, row by row.
  vd r[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      r[i][j] = R[i][j] - F[i][j];
      if constexpr (kMultipliers) r[i][j] -= alpha_d * load(lambda + (3 * i + j) * kLanes);
      if constexpr (kDamped) r[i][j] -= damp * dF[i][j];
    }
  const vd s = 1.0 + damp;
  const vd a00 = s * load(b.B[0]) + alpha_d, a01 = s * load(b.B[1]), a02 = s * load(b.B[2]);
  const vd a11 = s * load(b.B[3]) + alpha_d, a12 = s * load(b.B[4]), a22 = s * load(b.B[5]) + alpha_d;
  // Inverse of the symmetric A by cofactors (A is positive definite: alpha > 0).
  const vd c00 = a11 * a22 - a12 * a12, c01 = a02 * a12 - a01 * a22, c02 = a01 * a12 - a02 * a11;
  const vd c11 = a00 * a22 - a02 * a02, c12 = a01 * a02 - a00 * a12, c22 = a00 * a11 - a01 * a01;
  const vd inv_det = 1.0 / (a00 * c00 + a01 * c01 + a02 * c02);
  const vd Ai[3][3] = {{c00 * inv_det, c01 * inv_det, c02 * inv_det},
                       {c01 * inv_det, c11 * inv_det, c12 * inv_det},
                       {c02 * inv_det, c12 * inv_det, c22 * inv_det}};
  vd M[3][3];  // dLambda; the position update is dx_a = w_a M b_a
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) M[i][j] = r[i][0] * Ai[0][j] + r[i][1] * Ai[1][j] + r[i][2] * Ai[2][j];
  if constexpr (kMultipliers)
    for (int k = 0; k < 9; ++k) {
      const vd l = load(lambda + k * kLanes) + M[k / 3][k % 3];
      std::memcpy(lambda + k * kLanes, &l, sizeof(vd));
    }
  // F after the deviatoric update: F + M B.
  const vd Bxx = load(b.B[0]), Bxy = load(b.B[1]), Bxz = load(b.B[2]), Byy = load(b.B[3]), Byz = load(b.B[4]),
           Bzz = load(b.B[5]);
  for (int i = 0; i < 3; ++i) {
    const vd m0 = M[i][0], m1 = M[i][1], m2 = M[i][2];
    F[i][0] += m0 * Bxx + m1 * Bxy + m2 * Bxz;
    F[i][1] += m0 * Bxy + m1 * Byy + m2 * Byz;
    F[i][2] += m0 * Bxz + m1 * Byz + m2 * Bzz;
  }
  // Hydrostatic: C_H = det F - 1, gradient cof(F) b_a; Schur entry tr(cof B cof^T).
  vd cof[3][3];
  cofactor(F, cof);
  const vd J = F[0][0] * cof[0][0] + F[1][0] * cof[1][0] + F[2][0] * cof[2][0];
  vd a_vol = vd{}, rate = vd{};
  for (int i = 0; i < 3; ++i) {
    const vd c0 = cof[i][0], c1 = cof[i][1], c2 = cof[i][2];
    a_vol += c0 * (c0 * Bxx + c1 * Bxy + c2 * Bxz) + c1 * (c0 * Bxy + c1 * Byy + c2 * Byz) + c2 * (c0 * Bxz + c1 * Byz + c2 * Bzz);
    if constexpr (kDamped) rate += c0 * dF[i][0] + c1 * dF[i][1] + c2 * dF[i][2];
  }
  vd r_vol = 1.0 - J;
  if constexpr (kMultipliers) r_vol -= alpha_h * load(lambda + 9 * kLanes);
  if constexpr (kDamped) r_vol -= damp * rate;
  const vd dl = vol_on * r_vol / (s * a_vol + alpha_h);
  if constexpr (kMultipliers) {
    const vd l = load(lambda + 9 * kLanes) + dl;
    std::memcpy(lambda + 9 * kLanes, &l, sizeof(vd));
  }
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) M[i][j] += dl * cof[i][j];
  apply_update(b, count, X, W, M, c);
  if (!residual) return 0.0;
  // The change of F this solve made: M B.
  vd dF2 = vd{};
  for (int i = 0; i < 3; ++i) {
    const vd m0 = M[i][0], m1 = M[i][1], m2 = M[i][2];
    const vd d0 = m0 * Bxx + m1 * Bxy + m2 * Bxz, d1 = m0 * Bxy + m1 * Byy + m2 * Byz, d2 = m0 * Bxz + m1 * Byz + m2 * Bzz;
    dF2 += d0 * d0 + d1 * d1 + d2 * d2;
  }
  double sum = 0.0;
  for (int l = 0; l < count; ++l) sum += dF2[l];
  return sum;
}

template <bool kDamped, bool kMultipliers>
ARNAV_INLINE double solve_corotated_range(const TetBatch* batches, const int* count, const int* index, int num, double* X,
                                          const double* XP, const double* W, double* rotation, double* lambda, double h,
                                          bool residual) {
  double sum = 0.0;
  for (int i = 0; i < num; ++i) {
    const int k = index[i];
    sum += solve_corotated_batch<kDamped, kMultipliers>(batches[k], count[k], X, XP, W, rotation + 4L * kLanes * k,
                                                        kMultipliers ? lambda + 10L * kLanes * k : nullptr, h, residual);  // no multipliers: lambda is null
  }
  return sum;
}

}  // namespace

ARNAV_XPBD_CLONES
double solve_nh_batches(const TetBatch* batches, const int* count, const int* index, int num, double* X, const double* XP,
                        const double* W, const SweepParams& params) {
  return params.damped ? solve_range<true>(batches, count, index, num, X, XP, W, params.h_s, params.residual)
                       : solve_range<false>(batches, count, index, num, X, XP, W, params.h_s, params.residual);
}

ARNAV_XPBD_CLONES
double solve_corotated_batches(const TetBatch* batches, const int* count, const int* index, int num, double* X,
                               const double* XP, const double* W, double* rotation, double* lambda, const SweepParams& params) {
  const double h = params.h_s;
  const bool r = params.residual;
  if (params.damped)
    return params.multipliers
               ? solve_corotated_range<true, true>(batches, count, index, num, X, XP, W, rotation, lambda, h, r)
               : solve_corotated_range<true, false>(batches, count, index, num, X, XP, W, rotation, lambda, h, r);
  return params.multipliers ? solve_corotated_range<false, true>(batches, count, index, num, X, XP, W, rotation, lambda, h, r)
                            : solve_corotated_range<false, false>(batches, count, index, num, X, XP, W, rotation, lambda, h, r);
}

ARNAV_XPBD_CLONES
double corotated_energy(const TetBatch* batches, const int* count, int begin, int end, const double* X,
                        const double* rotation, int* inverted) {
  double energy = 0.0;
  int bad = 0;
  for (int k = begin; k < end; ++k) {
    const TetBatch& b = batches[k];
    const Corners c = gather(b, X);
    vd F[3][3];
    deformation_gradient(b, c, F);
    vd q[4];
    for (int i = 0; i < 4; ++i) q[i] = load(rotation + 4L * kLanes * k + i * kLanes);
    vd R[3][3];
    refine_rotation_lanes(F, q, R);  // R of the last sweep, one refinement (not stored)
    vd dev = vd{};
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) dev += (F[i][j] - R[i][j]) * (F[i][j] - R[i][j]);
    const vd J = determinant(F);
    const vd e = load(b.mu_V) * dev + 0.5 * load(b.lambda_V) * (J - 1.0) * (J - 1.0);
    for (int l = 0; l < count[k]; ++l) {
      energy += e[l];
      if (!(J[l] > 0.0)) ++bad;
    }
  }
  *inverted += bad;
  return energy;
}

ARNAV_XPBD_CLONES
double nh_energy(const TetBatch* batches, const int* count, int begin, int end, const double* X, int* inverted) {
  double energy = 0.0;
  int bad = 0;
  for (int k = begin; k < end; ++k) {
    const TetBatch& b = batches[k];
    const Corners c = gather(b, X);
    vd F[3][3];
    deformation_gradient(b, c, F);
    const vd J = determinant(F);
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
