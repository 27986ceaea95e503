#include "host/app/cpu_partition.hpp"

#include <pthread.h>
#include <sched.h>

#include <cerrno>
#include <cstdio>
#include <fstream>
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

double load_average_1min() {
  std::ifstream in("/proc/loadavg");
  double load = -1.0;
  in >> load;
  return in ? load : -1.0;
}

CpuPlan plan_cpu_partition(const std::string& mode, bool overlay, bool model) {
  return plan_cpu_partition(mode, overlay, model, mode == "auto" ? load_average_1min() : 0.0);
}

CpuPlan plan_cpu_partition(const std::string& mode, bool overlay, bool model, double load_1min) {
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
  if (mode == "auto" && !(load_1min >= 0.0 && load_1min < static_cast<double>(cpus.size()))) {
    char text[160];
    std::snprintf(text, sizeof text, "off (auto: load average %.2f, not below the %zu CPUs: the machine is busy with other work)", load_1min,
                  cpus.size());
    p.reason = text;
    return p;
  }
  p.active = true;
  p.model_cpus = {cpus.back()};
  p.render_cpus.assign(cpus.begin(), cpus.end() - 1);
  if (mode == "on") {
    p.reason = "on";
  } else {
    char text[120];
    std::snprintf(text, sizeof text, "on (auto: load average %.2f below the %zu CPUs)", load_1min, cpus.size());
    p.reason = text;
  }
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
