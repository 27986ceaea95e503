#include "host/sim/fem/blas_threads.hpp"

#include <dlfcn.h>

namespace arnav::host {
namespace {

template <class F>
F openblas_entry(const char* name) {
  // RTLD_DEFAULT: the symbol is there when libblas.so.3 resolved to OpenBLAS (it pulls in
  // libopenblas.so.0); reference BLAS has no openblas_* entry points.
  return reinterpret_cast<F>(dlsym(RTLD_DEFAULT, name));
}

}  // namespace

BlasInfo blas_info() {
  BlasInfo info;
  const auto get_config = openblas_entry<char* (*)()>("openblas_get_config");
  const auto get_threads = openblas_entry<int (*)()>("openblas_get_num_threads");
  const auto get_core = openblas_entry<char* (*)()>("openblas_get_corename");
  if (get_config == nullptr || get_threads == nullptr) return info;
  info.openblas = true;
  info.config = get_config();
  if (get_core != nullptr) info.config += std::string(" core ") + get_core();
  info.threads = get_threads();
  return info;
}

bool set_blas_threads(int threads) {
  const auto set = openblas_entry<void (*)(int)>("openblas_set_num_threads");
  if (set == nullptr) return false;
  set(threads);
  return true;
}

}  // namespace arnav::host
