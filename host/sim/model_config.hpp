#pragma once
// Which tissue model a scene asks for and how its solver is set. Filled from the scene
// file (host/scene) and by benchmarks; read by make_tissue_model (host/sim).
#include <string>

namespace arnav::host {

struct ModelConfig {
  std::string kind = "xpbd";          // "mass_spring" | "xpbd" | "corotational_fem"
  std::string integrator;             // mass_spring: "explicit" | "semi_implicit" | "local_global";
                                      // corotational_fem: "implicit_euler" | "quasi_static"
  std::string energy{};               // xpbd: "corotated" (default when empty) | "neo_hookean"
  std::string material_model{};       // corotational_fem: "corotational_linear" (default when empty) |
                                      // "stable_neo_hookean" (projected Newton; iterations = Newton
                                      // iterations per step; stable_neo_hookean_fem.hpp)
  std::string linear_solver;          // corotational_fem: "cholmod" | "eigen_ldlt" | "pcg" | "pcg_jacobi";
                                      // mass_spring semi_implicit: "jacobi" (default) | "laplacian"
  int iterations = 10;                // XPBD iterations per substep; PCG max iterations;
                                      // mass_spring local_global: iterations per substep
  int substeps = 1;                   // substeps per step(dt)
  double tolerance = 1e-6;            // relative residual for iterative solves
  int refactor_every = 1;             // FEM: steps between numeric refactorisations
  int threads = 1;                    // worker threads for the model's parallel loops
  bool refactor_in_background = false;  // FEM pcg: refactorise on a worker thread while PCG keeps
                                        // the last factor (docs/sim-fem.md); false = inline, deterministic
  int blas_threads = 0;               // FEM: OpenBLAS threads for CHOLMOD (0 = leave the process
                                      // setting, e.g. OPENBLAS_NUM_THREADS); needs OpenBLAS when > 1
  bool single_precision_preconditioner = false;  // FEM pcg: apply the factor in float (half the
                                                 // memory traffic; PCG corrects the rounding)
};

}  // namespace arnav::host
