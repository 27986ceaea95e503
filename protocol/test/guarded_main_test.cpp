// guarded_main: whatever escapes a program's body ends as exit 3 and one line naming the
// program, never std::terminate; the body's own exit codes pass through.
#include <gtest/gtest.h>

#include <new>
#include <stdexcept>

#include "protocol/guarded_main.hpp"

namespace arnav {
namespace {

TEST(GuardedMain, PassesTheBodysExitCode) {
  EXPECT_EQ(guarded_main("prog", [] { return 0; }), 0);
  EXPECT_EQ(guarded_main("prog", [] { return 2; }), 2);
}

TEST(GuardedMain, EscapingExceptionsExitThreeWithTheProgramName) {
  testing::internal::CaptureStderr();
  EXPECT_EQ(guarded_main("arnav-x", []() -> int { throw std::runtime_error("no benchmark rows to plot"); }), kExitInternalError);
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("arnav-x: internal error: no benchmark rows to plot"), std::string::npos) << err;

  testing::internal::CaptureStderr();
  EXPECT_EQ(guarded_main("arnav-x", []() -> int { throw 42; }), kExitInternalError);
  EXPECT_NE(testing::internal::GetCapturedStderr().find("arnav-x: internal error: unknown exception"), std::string::npos);

  testing::internal::CaptureStderr();
  EXPECT_EQ(guarded_main("arnav-x", []() -> int { throw std::bad_alloc(); }), kExitInternalError);
  EXPECT_NE(testing::internal::GetCapturedStderr().find("arnav-x: out of memory"), std::string::npos);
}

}  // namespace
}  // namespace arnav
