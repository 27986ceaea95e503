#pragma once
// Real-time settings of the NDI polling thread (docs/appliance.md, `realtime:`).
// Why: the appliance's latency budget (last byte of a BX reply to LCM publish, p99 <= 100 us)
// and its zero-lost-frame soak at 400 Hz are lost to two things the code cannot fix itself:
// CPUs that fall into deep idle states between frames (a wake-up then costs tens of us), and
// a polling thread that waits behind other work on a busy box. The fixes are the standard
// Linux ones: a PM QoS CPU-latency request held while the appliance runs, and SCHED_FIFO
// for the one thread that talks to the tracker. Both need root (or CAP_SYS_NICE and write
// access to /dev/cpu_dma_latency); when refused, the appliance says so and carries on.
#include <string>

namespace arnav::app {

struct RealtimeConfig {
  // PM QoS request in microseconds held while running; negative: leave the CPU idle policy alone.
  int cpu_latency_us = 0;
  // SCHED_FIFO priority (1-99) of the polling thread; 0: normal scheduling. On by default:
  // the appliance is a dedicated box and the latency target needs it (docs/benchmarks.md).
  int priority = 50;
};

// Holds a PM QoS CPU-latency request for its lifetime (the kernel drops it when the file
// descriptor closes, also if the process dies).
class CpuLatencyRequest {
 public:
  // device: the PM QoS device (tests pass an ordinary file to check what is written).
  explicit CpuLatencyRequest(int latency_us, const std::string& device = "/dev/cpu_dma_latency");
  ~CpuLatencyRequest();
  CpuLatencyRequest(const CpuLatencyRequest&) = delete;
  CpuLatencyRequest& operator=(const CpuLatencyRequest&) = delete;

  bool held() const { return fd_ >= 0; }
  // Why the request is not held (empty when held), naming the device and the fix.
  const std::string& error() const { return error_; }

 private:
  int fd_ = -1;
  std::string error_;
};

// Puts the calling thread under SCHED_FIFO at `priority` (1-99), with reset-on-fork so
// processes it starts run normally. Returns an empty string on success, else why not and
// what to do. priority 0 does nothing and succeeds.
std::string make_this_thread_realtime(int priority);

}  // namespace arnav::app
