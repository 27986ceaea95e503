#include "hil_tests/scenarios/can_run.hpp"

#include <poll.h>
#include <sys/mount.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "hil_tests/bench/namespaces.hpp"
#include "protocol/channels.hpp"
#include "protocol/clock.hpp"

namespace arnav::hil {
namespace {

std::string env_or(const char* name, const char* fallback) {
  const char* v = std::getenv(name);
  return v && *v ? v : fallback;
}

}  // namespace

std::string can_sim_exe() { return env_or("ARNAV_CAN_SIM_EXE", ARNAV_CAN_SIM_EXE); }
std::string can_tool_exe() { return env_or("ARNAV_CAN_TOOL_EXE", ARNAV_CAN_TOOL_EXE); }
std::string can_appliance_exe() { return env_or("ARNAV_APPLIANCE_EXE", ARNAV_APPLIANCE_EXE); }

CanCapture::CanCapture(const std::string& url) : bus_(url) {
  good_ = bus_.good();
  if (!good_) return;
  bus_.subscribe(std::string(channels::kInput), &CanCapture::on_input, this);
  bus_.subscribe(std::string(channels::kEvents), &CanCapture::on_event, this);
  bus_.subscribe(channels::health("can"), &CanCapture::on_health, this);
  bus_.subscribe(std::string(channels::kInputState), &CanCapture::on_state, this);
  thread_ = std::thread([this] {
    while (!stop_.load()) bus_.handleTimeout(50);
  });
}

CanCapture::~CanCapture() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
}

void CanCapture::on_input(const lcm::ReceiveBuffer*, const std::string&, const input_event_t* m) {
  const std::int64_t now = monotonic_us();
  std::lock_guard lock(mutex_);
  inputs_.push_back(*m);
  input_arrivals_.push_back(now);
}
void CanCapture::on_event(const lcm::ReceiveBuffer*, const std::string&, const appliance_event_t* m) {
  std::lock_guard lock(mutex_);
  events_.push_back(*m);
}
void CanCapture::on_health(const lcm::ReceiveBuffer*, const std::string&, const device_health_t* m) {
  std::lock_guard lock(mutex_);
  health_.push_back(*m);
}
void CanCapture::on_state(const lcm::ReceiveBuffer*, const std::string&, const input_event_t* m) {
  std::lock_guard lock(mutex_);
  states_.push_back(*m);
}
std::vector<input_event_t> CanCapture::states() const {
  std::lock_guard lock(mutex_);
  return states_;
}
std::vector<input_event_t> CanCapture::inputs() const {
  std::lock_guard lock(mutex_);
  return inputs_;
}
std::vector<std::int64_t> CanCapture::input_arrivals() const {
  std::lock_guard lock(mutex_);
  return input_arrivals_;
}
std::vector<appliance_event_t> CanCapture::events() const {
  std::lock_guard lock(mutex_);
  return events_;
}
std::vector<device_health_t> CanCapture::health() const {
  std::lock_guard lock(mutex_);
  return health_;
}
std::size_t CanCapture::count_inputs(const std::string& name, std::int8_t state) const {
  std::lock_guard lock(mutex_);
  std::size_t n = 0;
  for (const auto& i : inputs_) n += i.input_name == name && i.state == state;
  return n;
}
std::size_t CanCapture::count_events(const std::string& code) const {
  std::lock_guard lock(mutex_);
  std::size_t n = 0;
  for (const auto& e : events_) n += e.code == code;
  return n;
}
bool CanCapture::wait_for(const std::function<bool(const CanCapture&)>& pred, double timeout_s) const {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (!pred(*this)) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return true;
}
std::string CanCapture::event_log() const {
  std::lock_guard lock(mutex_);
  std::string s = "--- events ---\n";
  for (const auto& e : events_) s += e.code + ": " + e.text + "\n";
  s += "--- inputs ---\n";
  for (const auto& i : inputs_)
    s += i.input_name + (i.state == input_event_t::STATE_PRESSED ? " pressed" : " released") + " cause " + std::to_string(i.cause) + "\n";
  return s;
}

std::string CanRun::bus_name() const { return options_.path == CanPath::SocketCan ? "vcan0" : "slcan:/dev/ttyS0"; }

std::vector<std::string> CanRun::shim_env() const {
  if (options_.path == CanPath::SocketCan) return {"LD_PRELOAD=" ARNAV_CAN_SHIM_LIB, "ARNAV_HIL_CAN_DIR=" + dir_};
  return {"LD_PRELOAD=" ARNAV_SERIAL_SHIM_LIB};
}

std::string CanRun::start(const CanRunOptions& o) {
  options_ = o;
  if (can_appliance_exe().empty()) return "arnav-appliance is not built in this tree";
  if (const std::string why = enter_bench_namespaces(); !why.empty()) return why;
  if (o.path == CanPath::Slcan && (!std::filesystem::exists("/sys/class/tty/ttyS0") || !std::filesystem::exists("/dev/ttyS0")))
    return "no /dev/ttyS0 with a sysfs entry on this machine: nothing to bind the slcan pty over";
  if (o.path == CanPath::Slcan) {
    // A simulator killed earlier in this test process (private mount namespace) may have
    // left its mounts over /dev/ttyS0, the top one a pty that no longer exists: take them
    // down so this run's simulator mounts over the real node again.
    while (::umount2("/dev/ttyS0", MNT_DETACH) == 0) {
    }
  }
  dir_ = make_temp_dir("arnav-can");
  config_path_ = dir_ + "/appliance.yaml";
  {
    std::ofstream cfg(config_path_);
    cfg << "lcm_url: \"" << kLcmUrl << "\"\nhealth_rate_hz: 5\nsecurity: off\n"
        << "can:\n  interface: " << bus_name() << "\n  priority: " << o.appliance_priority << "\n";
    if (o.path == CanPath::Slcan) cfg << "  bitrate: 500000\n  status_poll_ms: " << o.status_poll_ms << "\n";
    cfg << "  nodes:\n"
        << "    - {name: pedal, heartbeat: 0x10, timeout_ms: " << o.pedal_timeout_ms << "}\n"
        << "    - {name: grasper, periodic_id: 0x185, timeout_ms: " << o.grasper_timeout_ms << "}\n"
        << "  inputs:\n"
        << "    - {name: pedal_cut, node: pedal, id: 0x190, byte: 0, bit: 0, debounce_ms: " << o.pedal_debounce_ms << "}\n"
        << "    - {name: pedal_accept, node: pedal, id: 0x190, byte: 0, bit: 1, active: low, debounce_ms: " << o.pedal_debounce_ms << "}\n"
        << "    - {name: pedal_analog, node: pedal, id: 0x191, byte: 1, size: 2, range: [200, 800], debounce_ms: 0}\n"
        << "    - {name: grasper_close, node: grasper, id: 0x185, byte: 0, bit: 7, debounce_ms: 10}\n";
    cfg << o.extra_config;
  }
  lcm_ = std::make_unique<CanCapture>(kLcmUrl);
  if (!lcm_->good()) return "cannot open LCM at " + std::string(kLcmUrl);
  std::vector<std::string> sim_argv = {can_sim_exe(), "--config", config_path_, "--control", dir_ + "/control.sock", "--log", dir_ + "/bus.log"};
  if (o.path == CanPath::SocketCan) {
    sim_argv.insert(sim_argv.end(), {"--socketcan", dir_, "--interface", "vcan0"});
  } else {
    sim_argv.insert(sim_argv.end(), {"--pty-link", dir_ + "/slcan", "--bind-over", "/dev/ttyS0"});
  }
  sim_argv.insert(sim_argv.end(), o.sim_args.begin(), o.sim_args.end());
  sim_ = std::make_unique<ChildProcess>(sim_argv, std::vector<std::string>{}, dir_ + "/sim.log", true, o.sim_priority);
  const auto ready = sim_->read_line(20.0);
  if (!ready || ready->rfind("READY ", 0) != 0) throw std::runtime_error("arnav-can-sim did not start:\n" + sim_->log_tail());
  std::vector<std::string> env = o.path == CanPath::SocketCan && !o.with_shim ? std::vector<std::string>{} : shim_env();
  env.insert(env.end(), o.appliance_env.begin(), o.appliance_env.end());
  appliance_ = std::make_unique<ChildProcess>(std::vector<std::string>{can_appliance_exe(), config_path_}, env, dir_ + "/appliance.log");
  return "";
}

CanRun::~CanRun() {
  if (appliance_) appliance_->stop();
  if (sim_) sim_->stop();
  lcm_.reset();
  if (!dir_.empty() && !std::getenv("ARNAV_HIL_KEEP")) std::filesystem::remove_all(dir_);
}

std::string CanRun::inject(const std::string& command) {
  const int fd = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  sockaddr_un me{}, sim{};
  me.sun_family = sim.sun_family = AF_UNIX;
  if (fd < 0 || ::bind(fd, reinterpret_cast<sockaddr*>(&me), sizeof(sa_family_t)) != 0) return "ERROR socket";
  const std::string path = dir_ + "/control.sock";
  std::strncpy(sim.sun_path, path.c_str(), sizeof sim.sun_path - 1);
  std::string answer = "ERROR no answer";
  if (::sendto(fd, command.data(), command.size(), 0, reinterpret_cast<sockaddr*>(&sim), sizeof sim) >= 0) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 5000) > 0) {
      char buf[2048];
      const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
      answer.assign(buf, n > 0 ? static_cast<std::size_t>(n) : 0);
    }
  }
  ::close(fd);
  return answer;
}

int CanRun::stop_appliance(double timeout_s) {
  const int rc = appliance_ ? appliance_->stop(15, timeout_s) : -1;
  return rc;
}

std::string CanRun::logs() const {
  std::string s;
  if (sim_) s += "--- arnav-can-sim ---\n" + sim_->log_tail();
  if (appliance_) s += "\n--- arnav-appliance ---\n" + appliance_->log_tail();
  return s;
}

}  // namespace arnav::hil
