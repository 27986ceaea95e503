#pragma once
// One end-to-end run of the CAN bench (docs/can.md): arnav-can-sim serving either a
// SocketCAN bus (reached through the test-only can_shim) or an slcan adapter on a pty
// bind-mounted over /dev/ttyS0 (reached through libserialport and the serial shim), the
// real arnav-appliance with a `can:` configuration, and an LCM capture of what it
// publishes (input_event_t, CAN health, events), all inside the bench's private mount +
// network namespaces.
#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <lcm/lcm-cpp.hpp>

#include "arnav/appliance_event_t.hpp"
#include "arnav/device_health_t.hpp"
#include "arnav/input_event_t.hpp"
#include "hil_tests/bench/child_process.hpp"

namespace arnav::hil {

enum class CanPath { SocketCan, Slcan };

struct CanRunOptions {
  CanPath path = CanPath::SocketCan;
  bool with_shim = true;             // SocketCAN: preload the can_shim (false: the kernel's AF_CAN)
  int pedal_debounce_ms = 20;
  int pedal_timeout_ms = 300;
  int grasper_timeout_ms = 100;
  int status_poll_ms = 100;          // slcan F polling
  std::vector<std::string> sim_args;
  std::vector<std::string> appliance_env;
  int appliance_priority = 50;       // can.priority of the appliance (50 as shipped; 0: normal)
  int sim_priority = 0;              // SCHED_FIFO for the simulator (0: normal)
  // Appended to the appliance configuration (top-level sections, e.g. `port: sim` with
  // tools and a `swab:` on one of the inputs above).
  std::string extra_config;
};

std::string can_sim_exe();
std::string can_tool_exe();
std::string can_appliance_exe();  // empty when arnav-appliance is not built

class CanCapture {
 public:
  explicit CanCapture(const std::string& url);
  ~CanCapture();
  bool good() const { return good_; }
  std::vector<input_event_t> inputs() const;
  // Arrival times (this process's monotonic clock) of inputs(), index for index.
  std::vector<std::int64_t> input_arrivals() const;
  std::vector<appliance_event_t> events() const;
  std::vector<device_health_t> health() const;
  std::vector<input_event_t> states() const;  // ARNAV_INPUT_STATE snapshots
  std::size_t count_inputs(const std::string& name, std::int8_t state) const;
  std::size_t count_events(const std::string& code) const;
  bool wait_for(const std::function<bool(const CanCapture&)>& pred, double timeout_s) const;
  std::string event_log() const;

 private:
  void on_input(const lcm::ReceiveBuffer*, const std::string&, const input_event_t* m);
  void on_event(const lcm::ReceiveBuffer*, const std::string&, const appliance_event_t* m);
  void on_health(const lcm::ReceiveBuffer*, const std::string&, const device_health_t* m);
  void on_state(const lcm::ReceiveBuffer*, const std::string&, const input_event_t* m);
  lcm::LCM bus_;
  bool good_ = false;
  std::atomic<bool> stop_{false};
  mutable std::mutex mutex_;
  std::vector<input_event_t> inputs_;
  std::vector<std::int64_t> input_arrivals_;
  std::vector<appliance_event_t> events_;
  std::vector<device_health_t> health_;
  std::vector<input_event_t> states_;
  std::thread thread_;
};

class CanRun {
 public:
  static constexpr const char* kLcmUrl = "udpm://239.255.76.67:7667?ttl=0";
  // Empty on success, else why the bench cannot run here (the test skips).
  std::string start(const CanRunOptions& options);
  ~CanRun();
  std::string inject(const std::string& command);  // "OK" or "ERROR ..."
  int stop_appliance(double timeout_s = 20.0);
  CanCapture& lcm() { return *lcm_; }
  const std::string& dir() const { return dir_; }
  const std::string& appliance_config() const { return config_path_; }
  std::string bus_name() const;   // "vcan0" or "slcan:/dev/ttyS0"
  std::vector<std::string> shim_env() const;  // what a tool needs to reach the bench bus
  std::string logs() const;

 private:
  std::string dir_, config_path_;
  CanRunOptions options_;
  std::unique_ptr<CanCapture> lcm_;
  std::unique_ptr<ChildProcess> sim_, appliance_;
};

}  // namespace arnav::hil
