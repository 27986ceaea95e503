#pragma once
// Timestamps in microseconds. Monotonic for intervals and latency, wall clock for logs.
#include <cstdint>

namespace arnav {

std::int64_t monotonic_us();  // CLOCK_MONOTONIC
std::int64_t wall_us();       // CLOCK_REALTIME

}  // namespace arnav
