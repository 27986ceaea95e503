#pragma once
// A constant symmetric positive definite n x n system, factored once by CHOLMOD
// (supernodal Cholesky) and solved for the three coordinates at once. The local/global
// integrator of the mass-spring model (Liu et al. 2013) keeps its system matrix
// M/h^2 + C/h + L (a scalar Laplacian: the same for x, y and z) in one of these and
// refactors only when h, the fixed set or the attachments change.
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <memory>
#include <string>

namespace arnav::host {

class PrefactoredSystem {
 public:
  using Matrix = Eigen::SparseMatrix<double, Eigen::ColMajor, int>;  // lower triangle used
  PrefactoredSystem();
  ~PrefactoredSystem();
  PrefactoredSystem(PrefactoredSystem&&) noexcept;
  PrefactoredSystem& operator=(PrefactoredSystem&&) noexcept;

  // Numeric factorisation of A (lower triangle); the symbolic analysis (fill-reducing
  // ordering) is redone only when the sparsity pattern differs from the last one.
  // Returns false (and message()) when A is not positive definite.
  bool factorize(const Matrix& A_lower);
  // x = A^-1 b for the three columns of b (n x 3). Needs a successful factorize().
  // With threads >= 2 one thread solves x and y, another z (the factor is shared, read
  // only; each thread has its own CHOLMOD workspace).
  void solve(const Eigen::MatrixX3d& b, Eigen::MatrixX3d& x, int threads = 1);

  bool ready() const { return ready_; }
  const std::string& message() const { return message_; }
  double last_factor_ms() const { return factor_ms_; }
  bool last_was_analysis() const { return analysed_now_; }
  long factor_nonzeros() const;  // entries of L (work per solve)

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  bool ready_ = false;
  bool empty_ = false;  // 0 x 0 system (every vertex fixed)
  bool analysed_now_ = false;
  double factor_ms_ = 0.0;
  std::string message_;
};

}  // namespace arnav::host
