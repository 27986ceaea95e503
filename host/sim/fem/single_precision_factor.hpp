#pragma once
// A single-precision copy of a supernodal CHOLMOD factor (L L^T = P A P^T) and its
// triangular solves, for use as a preconditioner. Applying a factor of the liver's matrix
// (nnz(L) 3.7 M) reads the whole factor twice per solve and is bound by memory
// bandwidth: in float it moves half the bytes. PCG corrects the rounding (float has ~7
// digits; PCG's tolerance here is 1e-4 or looser), so the result is that of the
// double-precision solve to the CG tolerance.
#include <Eigen/Core>
#include <vector>

struct cholmod_factor_struct;

namespace arnav::host {

class SinglePrecisionFactor {
 public:
  // Copies L (supernodal, LL^T, int indices, real); throws std::invalid_argument otherwise.
  void assign(const cholmod_factor_struct& L);
  bool empty() const { return values_.empty(); }
  // x = A^-1 b to single precision (x may not alias b).
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) const;

 private:
  int n_ = 0;
  std::vector<int> perm_, super_, row_start_, value_start_, rows_;
  std::vector<float> values_;
  mutable Eigen::VectorXf y_, t_;  // work vectors (one solve at a time)
};

}  // namespace arnav::host
