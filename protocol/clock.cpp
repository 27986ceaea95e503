#include "protocol/clock.hpp"

#include <ctime>

namespace arnav {
namespace {
std::int64_t read_us(clockid_t id) {
  timespec ts{};
  clock_gettime(id, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000 + ts.tv_nsec / 1000;
}
}  // namespace

std::int64_t monotonic_us() { return read_us(CLOCK_MONOTONIC); }
std::int64_t wall_us() { return read_us(CLOCK_REALTIME); }

}  // namespace arnav
