#include "hil_tests/scenarios/hil_run.hpp"

#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "hil_tests/bench/namespaces.hpp"

namespace arnav::hil {
namespace fs = std::filesystem;

namespace {
std::string env_or(const char* name, const char* fallback) {
  const char* v = std::getenv(name);
  return v && *v ? std::string(v) : std::string(fallback);
}
}  // namespace

std::string polaris_sim_exe() { return env_or("ARNAV_POLARIS_SIM_EXE", ARNAV_POLARIS_SIM_EXE); }
std::string appliance_exe() { return env_or("ARNAV_APPLIANCE_EXE", ARNAV_APPLIANCE_EXE); }
std::string host_exe() { return env_or("ARNAV_HOST_EXE", ARNAV_HOST_EXE); }
std::string serial_shim_lib() { return env_or("ARNAV_SERIAL_SHIM_LIB", ARNAV_SERIAL_SHIM_LIB); }

std::string HilRun::start(const HilRunOptions& o) {
  if (appliance_exe().empty()) return "arnav-appliance is not built in this tree";
  if (const std::string why = enter_bench_namespaces(); !why.empty()) return why;
  if (!fs::exists("/sys/class/tty/ttyS0") || !fs::exists("/dev/ttyS0"))
    return "no /dev/ttyS0 with a sysfs entry on this machine: nothing to bind the pty over";
  dir_ = make_temp_dir("arnav-hil");
  const std::string roms = env_or("ARNAV_DATA_DIR", ARNAV_DEFAULT_DATA_DIR) + "/ndi_roms/";

  // Simulator: the scenario's tools (same ROMs as the appliance loads), ground truth.
  std::vector<std::string> sim_argv = {polaris_sim_exe(), "--pty-link", dir_ + "/polaris", "--bind-over", "/dev/ttyS0",
                                       "--break-socket", dir_ + "/break.sock", "--control", dir_ + "/control.sock",
                                       "--truth", dir_ + "/truth.csv", "--events", dir_ + "/sim_events.jsonl", "--trace", dir_ + "/trace.txt",
                                       "--rate", std::to_string(o.rate_hz)};
  for (const auto& [name, rom] : o.tools) {
    sim_argv.push_back("--tool");
    sim_argv.push_back(name + "=" + roms + rom);
    tool_names_.push_back(name);
  }
  sim_argv.insert(sim_argv.end(), o.sim_args.begin(), o.sim_args.end());
  sim_ = std::make_unique<ChildProcess>(sim_argv, std::vector<std::string>{}, dir_ + "/sim.log", true, o.sim_priority);
  const auto ready = sim_->read_line(30.0);
  if (!ready || ready->rfind("READY ", 0) != 0) throw std::runtime_error("simulator did not get ready:\n" + sim_->log_tail());

  lcm_ = std::make_unique<LcmCapture>(kLcmUrl, o.key_file.empty() ? seal::BusSecurity::off() : seal::security_from_cli(o.key_file, "", "HilRun"));
  if (!lcm_->good()) throw std::runtime_error(std::string("cannot open LCM ") + kLcmUrl + " in the bench namespace");

  // Appliance: production configuration, serial port /dev/ttyS0 (libserialport path).
  {
    std::ofstream cfg(dir_ + "/appliance.yaml");
    cfg << "port: /dev/ttyS0\nbaud: 115200\nrate_hz: " << o.rate_hz << "\nlcm_url: \"" << kLcmUrl << "\"\nreply_mode: " << o.reply_mode
        << "\nrealtime: {cpu_latency_us: " << o.cpu_latency_us << ", priority: " << o.priority << "}\n"
        << (o.key_file.empty() ? std::string("security: off\n") : "security: {key_file: " + o.key_file + "}\n") << "tools:\n";
    for (const auto& [name, rom] : o.tools) cfg << "  - name: " << name << "\n    rom: " << roms << rom << "\n";
    cfg << o.extra_config;
  }
  appliance_ = std::make_unique<ChildProcess>(
      std::vector<std::string>{appliance_exe(), dir_ + "/appliance.yaml"},
      std::vector<std::string>{"LD_PRELOAD=" + serial_shim_lib(), "ARNAV_HIL_BREAK_SOCKET=" + dir_ + "/break.sock"},
      dir_ + "/appliance.log");
  return {};
}

HilRun::~HilRun() {
  appliance_.reset();
  sim_.reset();
  lcm_.reset();
  if (!dir_.empty() && std::getenv("ARNAV_HIL_KEEP") == nullptr) fs::remove_all(dir_);
}

std::string HilRun::inject(const std::string& command) {
  ChildProcess c({polaris_sim_exe(), "inject", "--control", dir_ + "/control.sock", command}, {}, dir_ + "/inject.log", true);
  const std::string answer = c.read_line(15.0).value_or("no answer");
  c.wait(15.0);
  return answer;
}

bool HilRun::wait_all_valid(std::size_t count, std::int64_t after_us, double timeout_s) const {
  return lcm_->wait_for(
      [&](const LcmCapture& l) {
        for (const auto& t : tool_names_)
          if (l.valid_after(t, after_us) < count) return false;
        return true;
      },
      timeout_s);
}

int HilRun::stop_appliance(double timeout_s) { return appliance_ ? appliance_->stop(15, timeout_s) : -1; }
int HilRun::stop_simulator(double timeout_s) { return sim_ ? sim_->stop(15, timeout_s) : -1; }

TruthTable HilRun::truth() const { return read_truth_csv(dir_ + "/truth.csv"); }

std::string HilRun::logs() const {
  std::string s;
  if (appliance_) s += "--- appliance log ---\n" + appliance_->log_tail(6000) + "\n";
  if (sim_) s += "--- simulator log ---\n" + sim_->log_tail(4000) + "\n";
  return s;
}

}  // namespace arnav::hil
