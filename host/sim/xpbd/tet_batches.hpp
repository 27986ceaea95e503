#pragma once
// XPBD tet constraints stored and solved in batches of kLanes tets that touch distinct
// vertices (structure of arrays inside a batch), so that one batch is solved with SIMD
// arithmetic across its tets. Two energies: fixed-corotated (see xpbd_model.hpp) and
// stable Neo-Hookean (Macklin & Mueller 2021), as follows.
//
// Energy per unit rest volume: Psi = mu/2 (|F|^2 - 3) + lambda/2 (det F - gamma)^2 with
// gamma = 1 + mu/lambda (rest is stress free). Linearised it is linear elasticity with
// Lame parameters (mu, lambda - mu), so lambda = lambda_0 + mu_0 for a material's
// (mu_0, lambda_0). Two constraints per tet, solved together as one 2x2 block:
//   C_D = |F|_F                 compliance 1/(mu V)      (deviatoric)
//   C_H = det F - gamma         compliance 1/(lambda V)  (hydrostatic)
// No polar decomposition. At rest (and any rotation of it) the two gradients are
// parallel (F/|F| and cof F = F); the coupled block then returns corrections that cancel
// exactly, so a rigid state gets no correction (solving the two one after the other
// would not: the rest state would drift).
// Frame World; units mm, kg, s, kPa.
#include <array>
#include <cstdint>
#include <vector>

namespace arnav::host::xpbd {

constexpr int kLanes = 8;  // tets per batch: one AVX-512 register of doubles

struct alignas(64) TetBatch {
  std::int32_t v[4][kLanes];  // vertex indices; unused lanes repeat lane 0 (never written back)
  double b[3][3][kLanes];     // b_a = row a-1 of Dm^-1 (a = 1..3): dF/dx_a = e_i b_a^T, b_0 = -(b_1+b_2+b_3)
  double B[6][kLanes];        // sum_a w_a b_a b_a^T (w inverse masses): xx, xy, xz, yy, yz, zz
  double inv_mu_V[kLanes];    // deviatoric compliance, 1/(kPa mm^3): 1/(mu V); corotated 1/(2 mu V)
  double inv_lambda_V[kLanes];  // hydrostatic compliance 1/(lambda V) (corotated, lambda = 0: 1, unused)
  double gamma[kLanes];       // Neo-Hookean: 1 + mu/lambda; corotated: 1 with a volume term, else 0
  double beta_s[kLanes];      // Rayleigh beta (stiffness damping), s
  double mu_V[kLanes];        // mu V and lambda V, for the energy
  double lambda_V[kLanes];
};

// The tets of a mesh in batches whose kLanes tets touch distinct vertices, in five groups:
// group 0 and 1 (the two halves of the mesh, which share no vertex), 2 and 3 (the two
// sides of the interface between the halves, which share no vertex either) and 4 (the
// seam: tets touching both sides). group[g] lists the batches of group g in sweep order;
// a batch belongs to at most one group (a batch in none is empty, kept for reuse).
struct TetBatches {
  std::vector<TetBatch> batches;
  std::vector<int> count;         // used lanes per batch
  std::vector<int> tet;           // batch * kLanes + lane -> mesh tet index (-1 unused)
  std::array<std::vector<int>, 5> group;
};

struct SweepParams {
  double h_s = 0.0;           // substep
  bool damped = false;        // some tet has beta > 0
  bool multipliers = false;   // corotated: keep Lagrange multipliers (iterations > 1)
  bool residual = true;       // compute the sweep's correction (else the solves return 0)
};

// Solves the blocks of batches index[0..num) once, in order (Gauss-Seidel from batch to
// batch, Jacobi across the lanes of a batch). One sweep per substep, so the Lagrange
// multipliers start and stay at zero and are not stored. X: positions (3 x n, column
// major), XP: positions at the substep start (read only when damped), W: inverse masses.
// Returns the sum over tets of |dF|^2, the squared Frobenius norm of the change of F
// this solve made (strain units): the sweep's correction (0 unless params.residual).
double solve_nh_batches(const TetBatch* batches, const int* count, const int* index, int num, double* X, const double* XP,
                        const double* W, const SweepParams& params);

// Fixed-corotated blocks (see xpbd_model.hpp) of batches index[0..num), once, in order.
// rotation: warm start of each tet's polar rotation, 4 x kLanes per batch (quaternion
// w, x, y, z), refined once per solve and stored back; lambda: multipliers, 10 x kLanes
// per batch (read and written when params.multipliers). Returns the sum over tets of
// |dF|^2 (as solve_nh_batches) when params.residual, else 0.
double solve_corotated_batches(const TetBatch* batches, const int* count, const int* index, int num, double* X,
                               const double* XP, const double* W, double* rotation, double* lambda, const SweepParams& params);

// Fixed-corotated stored energy and inverted tets (as nh_energy), R refined once from
// rotation (not stored).
double corotated_energy(const TetBatch* batches, const int* count, int begin, int end, const double* X,
                        const double* rotation, int* inverted);

// Stored energy (mN mm) of batches [begin, end) at positions X, and the number of tets
// with det F <= 0 (added to *inverted).
double nh_energy(const TetBatch* batches, const int* count, int begin, int end, const double* X, int* inverted);

}  // namespace arnav::host::xpbd
