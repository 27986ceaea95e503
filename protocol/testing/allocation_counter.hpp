#pragma once
// Test support: allocations made by this process so far (counted by the replacement
// operator new in allocation_counter.cpp, which the test links in its SOURCES).
namespace arnav::testing {
long allocation_count();
}
