#include "host/app/cpu_partition.hpp"

#include <pthread.h>
#include <sched.h>

#include <cerrno>
#include <cstring>
#include <ctime>
#include <stdexcept>

namespace arnav::host {

double thread_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

std::vector<int> current_thread_cpus() {
  cpu_set_t set;
  CPU_ZERO(&set);
  std::vector<int> out;
  if (pthread_getaffinity_np(pthread_self(), sizeof set, &set) != 0) return out;
  for (int c = 0; c < CPU_SETSIZE; ++c)
    if (CPU_ISSET(c, &set)) out.push_back(c);
  return out;
}

CpuPlan plan_cpu_partition(const std::string& mode, bool overlay, bool model) {
  CpuPlan p;
  if (mode == "off") {
    p.reason = "off (model.cpu_partition: off)";
    return p;
  }
  if (!overlay || !model) {
    if (mode == "on") throw std::invalid_argument("cpu_partition: on needs both an overlay (camera) and a model (scene)");
    p.reason = "off (auto: nothing to separate without both a camera and a model)";
    return p;
  }
  std::vector<int> cpus;
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) == 0)
    for (int c = 0; c < CPU_SETSIZE; ++c)
      if (CPU_ISSET(c, &set)) cpus.push_back(c);
  if (cpus.size() < 2) {
    if (mode == "on")
      throw std::invalid_argument("cpu_partition: on needs at least 2 CPUs, this process may use " + std::to_string(cpus.size()) +
                                  " (taskset/cgroup): use 'auto' or 'off'");
    p.reason = "off (auto: only " + std::to_string(cpus.size()) + " CPU available)";
    return p;
  }
  p.active = true;
  p.model_cpus = {cpus.back()};
  p.render_cpus.assign(cpus.begin(), cpus.end() - 1);
  p.reason = mode == "on" ? "on" : "on (auto)";
  return p;
}

std::string pin_current_thread(const std::vector<int>& cpus) {
  cpu_set_t set;
  CPU_ZERO(&set);
  for (int c : cpus) CPU_SET(c, &set);
  const int e = pthread_setaffinity_np(pthread_self(), sizeof set, &set);
  return e == 0 ? std::string() : std::string("pthread_setaffinity_np: ") + std::strerror(e);
}

}  // namespace arnav::host
