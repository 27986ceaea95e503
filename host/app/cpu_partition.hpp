#pragma once
// Cores of a navigation session (docs/overlay.md, "Threads and cores"): on a machine with
// few cores the tissue model and the overlay (JPEG decode, OpenGL on Mesa's software
// rasteriser, lens warp, compositing) compete for the same CPUs, and every frame that
// waits for a model step shows up in the motion-to-photon tail. Partitioned, the model
// thread (and the threads it starts: the solver's background factorisation) runs on a CPU
// of its own, the rendering thread and the rasteriser's threads on the others.
#include <string>
#include <vector>

namespace arnav::host {

struct CpuPlan {
  bool active = false;
  std::vector<int> render_cpus;   // the rendering thread, llvmpipe's threads, OpenCV's
  std::vector<int> model_cpus;    // the model thread and its workers
  std::string reason;             // why it is (not) active, for the summary
};

// mode "on" | "off" | "auto" (SessionConfig::model.cpu_partition); `overlay` and `model`:
// what the session renders and steps. Partitions the CPUs this process may run on
// (sched_getaffinity): the last one for the model, the others for rendering. "on" with
// fewer than 2 CPUs throws std::invalid_argument (the caller adds file:line).
// "auto" partitions only when the machine is not busy with other work when the session
// starts: 1-minute load average `load_1min` below the number of CPUs (a pinned thread
// cannot move to a CPU another process leaves idle: on the shared development machine,
// pinning made the latency worse, docs/benchmarks.md). Negative load: unknown (auto: off).
CpuPlan plan_cpu_partition(const std::string& mode, bool overlay, bool model, double load_1min);
CpuPlan plan_cpu_partition(const std::string& mode, bool overlay, bool model);  // load from /proc/loadavg

// The 1-minute load average (/proc/loadavg), -1 when unreadable.
double load_average_1min();

// The calling thread (and the threads it starts from now on) runs only on `cpus`.
// Returns an error text, empty on success.
std::string pin_current_thread(const std::vector<int>& cpus);

// CPU time of the calling thread, ms (CLOCK_THREAD_CPUTIME_ID).
double thread_cpu_ms();

// The CPUs the calling thread may run on now.
std::vector<int> current_thread_cpus();

}  // namespace arnav::host
