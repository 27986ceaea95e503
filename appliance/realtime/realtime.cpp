#include "appliance/realtime/realtime.hpp"

#include <cerrno>
#include <cstdint>
#include <cstring>

#include <fcntl.h>
#include <sched.h>
#include <unistd.h>

namespace arnav::app {

CpuLatencyRequest::CpuLatencyRequest(int latency_us, const std::string& device) {
  if (latency_us < 0) return;
  fd_ = ::open(device.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd_ < 0) {
    error_ = "cannot open " + device + " (" + std::strerror(errno) +
             "): CPU idle states stay as the kernel sets them. Run as root, or set realtime.cpu_latency_us: -1 to not ask";
    return;
  }
  // The PM QoS interface takes the request as a binary 32-bit integer in microseconds.
  const std::int32_t value = latency_us;
  if (::write(fd_, &value, sizeof value) != static_cast<ssize_t>(sizeof value)) {
    error_ = "cannot write to " + device + " (" + std::strerror(errno) + ")";
    ::close(fd_);
    fd_ = -1;
  }
}

CpuLatencyRequest::~CpuLatencyRequest() {
  if (fd_ >= 0) ::close(fd_);
}

std::string make_this_thread_realtime(int priority) {
  if (priority == 0) return {};
  const int lo = sched_get_priority_min(SCHED_FIFO), hi = sched_get_priority_max(SCHED_FIFO);
  if (priority < lo || priority > hi)
    return "realtime.priority " + std::to_string(priority) + " is outside SCHED_FIFO's " + std::to_string(lo) + "-" +
           std::to_string(hi);
  sched_param p{};
  p.sched_priority = priority;
  // pid 0 = the calling thread on Linux.
  if (sched_setscheduler(0, SCHED_FIFO | SCHED_RESET_ON_FORK, &p) != 0)
    return std::string("cannot make the NDI polling thread SCHED_FIFO ") + std::to_string(priority) + " (" +
           std::strerror(errno) + "): it runs with normal scheduling. Run as root or grant CAP_SYS_NICE, or set realtime.priority: 0";
  return {};
}

}  // namespace arnav::app
