#pragma once
// One end-to-end run of the HIL bench: simulated Polaris bound over /dev/ttyS0 in a
// private mount namespace, the real arnav-appliance on its production libserialport path
// (with the test-only serial shim preloaded), and an LCM capture over udpm on loopback
// inside a private network namespace.
#include <memory>
#include <string>
#include <vector>

#include "hil_tests/bench/child_process.hpp"
#include "hil_tests/bench/lcm_capture.hpp"
#include "hil_tests/bench/truth_table.hpp"

namespace arnav::hil {

struct HilRunOptions {
  double rate_hz = 60.0;
  std::string reply_mode = "bx";  // appliance: bx | tx
  std::vector<std::pair<std::string, std::string>> tools = {{"pointer", "8700340.rom"}, {"reference", "8700339.rom"}};
  std::vector<std::string> sim_args;  // extra simulator arguments
  // The appliance's realtime: section; the defaults are the production defaults, so the
  // end-to-end tests run the appliance as it is shipped.
  int cpu_latency_us = 0;             // realtime.cpu_latency_us (-1: no request)
  int priority = 50;                  // realtime.priority (0: normal scheduling)
  // SCHED_FIFO priority of the simulator (0: normal). A real Polaris is hardware with its own
  // clock; on a loaded bench machine a normally scheduled simulator answers late.
  int sim_priority = 0;
  // The bus key (docs/protocol.md, "Sealed bus"): the appliance seals and the capture opens
  // with it; empty: `security: off` in the appliance configuration.
  std::string key_file;
  // Appended to the appliance configuration (e.g. a `can:` section, docs/can.md).
  std::string extra_config;
};

// Paths of the executables under test (compile definitions or environment overrides).
std::string polaris_sim_exe();
std::string appliance_exe();  // empty when arnav-appliance is not built
std::string host_exe();       // empty when arnav-host is not built
std::string serial_shim_lib();

class HilRun {
 public:
  static constexpr const char* kLcmUrl = "udpm://239.255.76.67:7667?ttl=0";

  // Returns an empty string on success, else why the bench cannot run here (skip).
  std::string start(const HilRunOptions& options);
  ~HilRun();

  // Sends a fault command to the simulator; returns its answer ("OK" or "ERROR ...").
  std::string inject(const std::string& command);
  // Waits until every tool has published `count` valid poses after `after_us`.
  bool wait_all_valid(std::size_t count, std::int64_t after_us, double timeout_s) const;
  // SIGTERM to the appliance; its exit code (or -1 on timeout/kill).
  int stop_appliance(double timeout_s = 20.0);
  int stop_simulator(double timeout_s = 20.0);
  // Ground truth written by the simulator (read after stop_simulator()).
  TruthTable truth() const;
  // Logs for failure messages.
  std::string logs() const;

  const std::vector<std::string>& tool_names() const { return tool_names_; }
  LcmCapture& lcm() { return *lcm_; }
  const std::string& dir() const { return dir_; }

 private:
  std::string dir_;
  std::vector<std::string> tool_names_;
  std::unique_ptr<LcmCapture> lcm_;
  std::unique_ptr<ChildProcess> sim_;
  std::unique_ptr<ChildProcess> appliance_;
};

}  // namespace arnav::hil
