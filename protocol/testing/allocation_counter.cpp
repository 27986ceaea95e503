// Test support (tests only): a replacement global operator new that counts allocations, for
// tests that check a hot path does not allocate once warmed up. Linked into such a test
// binary only (its SOURCES); read the count through allocation_count().
#include "protocol/testing/allocation_counter.hpp"

#include <atomic>
#include <cstdlib>
#include <new>

namespace {
std::atomic<long> g_allocations{0};
}

void* operator new(std::size_t n) {
  ++g_allocations;
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

namespace arnav::testing {
long allocation_count() { return g_allocations.load(); }
}  // namespace arnav::testing
