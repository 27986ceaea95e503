#pragma once
// A bench test that cannot start its bench (no private network namespace, not root, an
// executable not built) is skipped where the bench cannot exist, and FAILS where it must:
// scripts/test sets ARNAV_BENCH_REQUIRED=1 when it runs as root and `unshare --net` works,
// so a green suite there has run every end-to-end test (issue 21: a suite that cannot pass
// by skipping). Facts of the machine that no bench can change (this kernel has AF_CAN, no
// /dev/ttyS0) stay plain skips; a program whose tests were all skipped is reported by ctest
// as "Skipped" (protocol/testing/skip_exit_code.cpp) and scripts/test lists them.
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>

namespace arnav::hil {

inline bool bench_required() {
  const char* v = std::getenv("ARNAV_BENCH_REQUIRED");
  return v != nullptr && std::strcmp(v, "1") == 0;
}

}  // namespace arnav::hil

// In a TEST body or SetUp: `why` non-empty means the bench could not start.
#define ARNAV_BENCH_OR_SKIP(why)                                                                                         \
  do {                                                                                                                   \
    if (const std::string arnav_why_ = (why); !arnav_why_.empty()) {                                                     \
      if (::arnav::hil::bench_required())                                                                                \
        FAIL() << "the HIL bench must run here (ARNAV_BENCH_REQUIRED=1, set by scripts/test as root with unshare) but " \
                  "could not start: "                                                                                    \
               << arnav_why_;                                                                                            \
      GTEST_SKIP() << "HIL bench not available: " << arnav_why_;                                                         \
    }                                                                                                                    \
  } while (0)
