#pragma once
// One run of the Ethernet-tracker bench: arnav-vega-sim listening on 127.0.0.1 inside the
// bench's private network namespace, the real arnav-appliance connected to it over TCP
// (ndi: {host, port}), and an LCM subscriber over udpm on loopback that keeps running
// statistics of what the appliance publishes (so a 10-minute soak at 400 Hz x 6 tools
// stores numbers, not 1.4 million messages).
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <lcm/lcm-cpp.hpp>

#include "arnav/device_health_t.hpp"
#include "arnav/tool_pose_t.hpp"
#include "hil_tests/bench/child_process.hpp"

namespace arnav::hil {

std::string vega_sim_exe();

struct VegaRunOptions {
  double rate_hz = 400.0;
  int tools = 6;
  std::vector<std::string> sim_faults;  // arnav-vega-sim --fault specs (AT_S after STREAM)
  int priority = 50;                    // appliance realtime.priority (as shipped)
  int cpu_latency_us = 0;               // appliance realtime.cpu_latency_us (as shipped)
  int sim_priority = 0;                 // SCHED_FIFO of the simulator (0: normal)
};

// What the subscriber saw, and what the appliance reported. Lost frames are the
// appliance's own count (device_health_t.dropped_frames: gaps in the device frame numbers
// it received, since bring-up); the subscriber's gaps (lcm_gaps) add the datagrams LCM
// lost on the way to this process, a separate figure. Latency is publish_time_mono_us -
// device_time_us of every pose (device timestamp -> published; both on this machine's
// CLOCK_MONOTONIC because the simulated device stamps frames with it) and arrival - device
// time at the subscriber.
struct VegaStats {
  std::uint64_t poses = 0;
  std::uint64_t frames = 0;        // new frame numbers of the first tool
  std::uint64_t lcm_gaps = 0;      // frame-number gaps seen by this subscriber, worst tool
  std::uint64_t repeated = 0;      // a frame number not above the last one, all tools
  std::uint64_t not_valid = 0;     // poses whose status is not VALID
  std::uint64_t bad_device_time = 0;  // device time after publish time (impossible)
  double max_gap_s = 0.0;          // longest wait between two poses of the first tool
  std::int64_t appliance_dropped_frames = -1;  // last device_health_t.dropped_frames (since bring-up)
  std::int64_t appliance_frames_total = -1;    // last device_health_t.frames_total (since bring-up)
  std::int64_t appliance_reconnects = -1;
  std::vector<float> publish_latency_us;   // device time -> published
  std::vector<float> arrival_latency_us;   // device time -> received by this subscriber
};

class VegaPoseMonitor {
 public:
  VegaPoseMonitor(const std::string& url, std::vector<std::string> tool_names);
  ~VegaPoseMonitor();
  bool good() const { return good_; }
  // Starts counting afresh (e.g. after warm-up).
  void reset();
  VegaStats snapshot() const;

 private:
  void on_pose(const lcm::ReceiveBuffer*, const std::string&, const tool_pose_t* m);
  void on_health(const lcm::ReceiveBuffer*, const std::string&, const device_health_t* m);

  lcm::LCM bus_;
  bool good_ = false;
  std::vector<std::string> tools_;
  std::atomic<bool> stop_{false};
  mutable std::mutex mutex_;
  VegaStats stats_;
  std::vector<std::int64_t> last_frame_;
  std::int64_t last_first_tool_arrival_us_ = 0;
  std::vector<std::uint64_t> lost_;
  std::thread thread_;
};

class VegaRun {
 public:
  static constexpr const char* kLcmUrl = "udpm://239.255.76.67:7667?ttl=0";
  // Empty on success, else why the bench cannot run here (the caller skips).
  std::string start(const VegaRunOptions& options);
  ~VegaRun();
  VegaPoseMonitor& monitor() { return *monitor_; }
  int stop_appliance(double timeout_s = 20.0);
  int stop_simulator(double timeout_s = 20.0);
  std::string logs() const;
  const std::string& dir() const { return dir_; }
  const std::vector<std::string>& tool_names() const { return tool_names_; }

 private:
  std::string dir_;
  std::vector<std::string> tool_names_;
  std::unique_ptr<VegaPoseMonitor> monitor_;
  std::unique_ptr<ChildProcess> sim_;
  std::unique_ptr<ChildProcess> appliance_;
};

// Percentile (0-100) of values by nearest rank; 0 when empty.
double percentile(std::vector<float> values, double p);

}  // namespace arnav::hil
