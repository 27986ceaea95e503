#pragma once
// Which BLAS CHOLMOD's supernodal factorisation and solves run on, and its thread count.
// Debian picks the BLAS at run time (the libblas.so.3 alternative): OpenBLAS when
// libopenblas0-pthread is installed (scripts/deps), else the single-threaded reference BLAS.
// OpenBLAS is found by its own entry points (dlsym), so nothing links against it directly.
#include <string>

namespace arnav::host {

struct BlasInfo {
  bool openblas = false;  // false: another BLAS (Debian's reference BLAS is single-threaded)
  std::string config;     // OpenBLAS build configuration and core kernel, e.g. "OpenBLAS 0.3.21 ... SkylakeX"
  int threads = 1;        // OpenBLAS threads of the process (1 for other BLAS)
};

BlasInfo blas_info();

// Sets OpenBLAS's thread count for the whole process (it is a process-wide setting).
// Returns false, changing nothing, when the BLAS is not OpenBLAS.
bool set_blas_threads(int threads);

}  // namespace arnav::host
