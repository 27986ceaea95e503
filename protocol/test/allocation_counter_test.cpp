// The test-support allocation counter sees allocations (so the hot-path tests that expect
// zero new allocations can fail), including those made inside the standard library.
#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

#include "protocol/testing/allocation_counter.hpp"

TEST(AllocationCounter, CountsNewAndLibraryAllocations) {
  const long before = arnav::testing::allocation_count();
  auto value = std::make_unique<int>(7);
  EXPECT_EQ(arnav::testing::allocation_count() - before, 1);
  std::vector<double> v(1000, *value);
  std::string long_text(200, 'x');
  EXPECT_GE(arnav::testing::allocation_count() - before, 3);
  EXPECT_EQ(v.size() + long_text.size(), 1200u);
}
