#include "host/sim/fem/single_precision_factor.hpp"

#include <cholmod.h>

#include <stdexcept>

namespace arnav::host {

void SinglePrecisionFactor::assign(const cholmod_factor& L) {
  if (!L.is_super || !L.is_ll || L.itype != CHOLMOD_INT || L.xtype != CHOLMOD_REAL || L.dtype != CHOLMOD_DOUBLE) {
    throw std::invalid_argument("SinglePrecisionFactor: needs a real supernodal LL^T CHOLMOD factor with int indices");
  }
  n_ = static_cast<int>(L.n);
  const int nsuper = static_cast<int>(L.nsuper);
  const int* perm = static_cast<const int*>(L.Perm);
  const int* super = static_cast<const int*>(L.super);
  const int* pi = static_cast<const int*>(L.pi);
  const int* px = static_cast<const int*>(L.px);
  const int* s = static_cast<const int*>(L.s);
  const double* x = static_cast<const double*>(L.x);
  perm_.assign(perm, perm + n_);
  super_.assign(super, super + nsuper + 1);
  row_start_.assign(pi, pi + nsuper + 1);
  value_start_.assign(px, px + nsuper + 1);
  rows_.assign(s, s + pi[nsuper]);
  values_.resize(static_cast<std::size_t>(px[nsuper]));
  for (std::size_t k = 0; k < values_.size(); ++k) values_[k] = static_cast<float>(x[k]);
  y_.resize(n_);
}

void SinglePrecisionFactor::solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) const {
  using Block = Eigen::Map<const Eigen::MatrixXf, 0, Eigen::OuterStride<>>;
  for (int k = 0; k < n_; ++k) y_[k] = static_cast<float>(b[perm_[k]]);  // y = P b
  const int nsuper = static_cast<int>(super_.size()) - 1;
  // Forward: L y = P b, supernode by supernode (column-major nsrow x nscol blocks whose
  // first nscol rows are the lower-triangular diagonal block).
  for (int j = 0; j < nsuper; ++j) {
    const int k1 = super_[j], nscol = super_[j + 1] - k1;
    const int ps = row_start_[j], nsrow = row_start_[j + 1] - ps;
    const Block Lj(values_.data() + value_start_[j], nsrow, nscol, Eigen::OuterStride<>(nsrow));
    auto yj = y_.segment(k1, nscol);
    Lj.topRows(nscol).triangularView<Eigen::Lower>().solveInPlace(yj);
    const int below = nsrow - nscol;
    if (below > 0) {
      t_.noalias() = Lj.bottomRows(below) * yj;
      for (int i = 0; i < below; ++i) y_[rows_[ps + nscol + i]] -= t_[i];
    }
  }
  // Backward: L^T z = y.
  for (int j = nsuper - 1; j >= 0; --j) {
    const int k1 = super_[j], nscol = super_[j + 1] - k1;
    const int ps = row_start_[j], nsrow = row_start_[j + 1] - ps;
    const Block Lj(values_.data() + value_start_[j], nsrow, nscol, Eigen::OuterStride<>(nsrow));
    auto yj = y_.segment(k1, nscol);
    const int below = nsrow - nscol;
    if (below > 0) {
      t_.resize(below);
      for (int i = 0; i < below; ++i) t_[i] = y_[rows_[ps + nscol + i]];
      yj.noalias() -= Lj.bottomRows(below).transpose() * t_;
    }
    Lj.topRows(nscol).triangularView<Eigen::Lower>().transpose().solveInPlace(yj);
  }
  x.resize(n_);
  for (int k = 0; k < n_; ++k) x[perm_[k]] = static_cast<double>(y_[k]);  // x = P^T z
}

}  // namespace arnav::host
