// Linked into every gtest executable (cmake/ArnavCommon.cmake, arnav_add_test): a test
// program in which every test was skipped and none failed exits with 77, which ctest reports
// as "Skipped" (SKIP_RETURN_CODE) rather than "Passed". A program with a failure keeps its
// failing exit code; one with at least one test run and passed stays a pass (its skips are
// listed in its own output). Matching "[  SKIPPED ]" in the output instead would turn a
// failing program with one skipped test into a skip.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>

namespace {

class SkipExitCode : public ::testing::EmptyTestEventListener {
  void OnTestProgramEnd(const ::testing::UnitTest& unit) override {
    if (unit.failed_test_count() == 0 && unit.successful_test_count() == 0 && unit.skipped_test_count() > 0) {
      std::fflush(nullptr);
      std::_Exit(77);
    }
  }
};

const bool registered = [] {
  ::testing::UnitTest::GetInstance()->listeners().Append(new SkipExitCode);
  return true;
}();

}  // namespace
