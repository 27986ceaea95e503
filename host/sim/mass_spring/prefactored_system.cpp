#include "host/sim/mass_spring/prefactored_system.hpp"

#include <Eigen/CholmodSupport>
#include <algorithm>
#include <chrono>
#include <vector>

namespace arnav::host {

namespace {
// Eigen keeps the CHOLMOD factor protected; its size is worth reporting (work per solve).
struct Llt : Eigen::CholmodSimplicialLLT<PrefactoredSystem::Matrix, Eigen::Lower> {
  const cholmod_factor* factor() const { return m_cholmodFactor; }
};
}  // namespace

struct PrefactoredSystem::Impl {
  Llt llt;
  std::vector<int> outer, inner;  // pattern of the last analysis
  bool analysed = false;
};

PrefactoredSystem::PrefactoredSystem() : impl_(std::make_unique<Impl>()) {
  impl_->llt.cholmod().print = 0;  // failures are reported through message()
}
PrefactoredSystem::~PrefactoredSystem() = default;
PrefactoredSystem::PrefactoredSystem(PrefactoredSystem&&) noexcept = default;
PrefactoredSystem& PrefactoredSystem::operator=(PrefactoredSystem&&) noexcept = default;

bool PrefactoredSystem::factorize(const Matrix& A) {
  const auto t0 = std::chrono::steady_clock::now();
  Impl& m = *impl_;
  const int cols = static_cast<int>(A.cols());
  const int nnz = static_cast<int>(A.nonZeros());
  const bool same = m.analysed && static_cast<int>(m.outer.size()) == cols + 1 && static_cast<int>(m.inner.size()) == nnz &&
                    std::equal(m.outer.begin(), m.outer.end(), A.outerIndexPtr()) &&
                    std::equal(m.inner.begin(), m.inner.end(), A.innerIndexPtr());
  analysed_now_ = !same;
  if (!same) {
    m.llt.analyzePattern(A);
    m.outer.assign(A.outerIndexPtr(), A.outerIndexPtr() + cols + 1);
    m.inner.assign(A.innerIndexPtr(), A.innerIndexPtr() + nnz);
    m.analysed = true;
  }
  m.llt.factorize(A);
  ready_ = m.llt.info() == Eigen::Success;
  message_ = ready_ ? "" : "system matrix is not positive definite";
  factor_ms_ = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return ready_;
}

void PrefactoredSystem::solve(const Eigen::MatrixX3d& b, Eigen::MatrixX3d& x) const { x = impl_->llt.solve(b); }

long PrefactoredSystem::factor_nonzeros() const {
  if (!ready_) return 0;
  const cholmod_factor* L = impl_->llt.factor();
  if (L == nullptr) return 0;
  return static_cast<long>(L->is_super ? L->xsize : L->nzmax);
}

}  // namespace arnav::host
