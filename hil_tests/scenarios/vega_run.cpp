#include "hil_tests/scenarios/vega_run.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include <pthread.h>
#include <sched.h>

#include "hil_tests/bench/namespaces.hpp"
#include "hil_tests/scenarios/hil_run.hpp"
#include "protocol/channels.hpp"
#include "protocol/clock.hpp"

namespace arnav::hil {
namespace fs = std::filesystem;

namespace {
std::string env_or(const char* name, const char* fallback) {
  const char* v = std::getenv(name);
  return v && *v ? std::string(v) : std::string(fallback);
}
}  // namespace

std::string vega_sim_exe() { return env_or("ARNAV_VEGA_SIM_EXE", ARNAV_VEGA_SIM_EXE); }

double percentile(std::vector<float> values, double p) {
  if (values.empty()) return 0.0;
  const auto rank = static_cast<std::size_t>(std::ceil(p / 100.0 * static_cast<double>(values.size())));
  const std::size_t k = std::min(values.size() - 1, rank == 0 ? 0 : rank - 1);
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(k), values.end());
  return values[k];
}

VegaPoseMonitor::VegaPoseMonitor(const std::string& url, std::vector<std::string> tool_names)
    : bus_(url), tools_(std::move(tool_names)), last_frame_(tools_.size(), -1), lost_(tools_.size(), 0) {
  good_ = bus_.good();
  if (!good_) return;
  stats_.publish_latency_us.reserve(1 << 20);
  stats_.arrival_latency_us.reserve(1 << 20);
  bus_.subscribe(std::string(channels::kPoseRegex), &VegaPoseMonitor::on_pose, this);
  bus_.subscribe(std::string(channels::kHealthRegex), &VegaPoseMonitor::on_health, this);
  thread_ = std::thread([this] {
    while (!stop_.load()) bus_.handleTimeout(50);
  });
  // The measurement must not lose datagrams to the load it measures under: the receiving
  // thread runs SCHED_FIFO (below the appliance's 50) when allowed; best effort.
  sched_param p{};
  p.sched_priority = 40;
  (void)pthread_setschedparam(thread_.native_handle(), SCHED_FIFO, &p);
}

VegaPoseMonitor::~VegaPoseMonitor() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
}

void VegaPoseMonitor::reset() {
  std::lock_guard lock(mutex_);
  const auto dropped = stats_.appliance_dropped_frames;
  const auto reconnects = stats_.appliance_reconnects;
  const auto frames_total = stats_.appliance_frames_total;
  stats_ = VegaStats{};
  stats_.appliance_dropped_frames = dropped;
  stats_.appliance_reconnects = reconnects;
  stats_.appliance_frames_total = frames_total;
  std::fill(lost_.begin(), lost_.end(), 0);
  last_first_tool_arrival_us_ = 0;
  // last_frame_ is kept: the first frame after a reset continues the sequence.
}

void VegaPoseMonitor::on_pose(const lcm::ReceiveBuffer*, const std::string&, const tool_pose_t* m) {
  const std::int64_t arrival = monotonic_us();
  std::lock_guard lock(mutex_);
  const auto it = std::find(tools_.begin(), tools_.end(), m->tool_name);
  if (it == tools_.end()) return;
  const auto i = static_cast<std::size_t>(it - tools_.begin());
  ++stats_.poses;
  if (m->status != tool_pose_t::STATUS_VALID) ++stats_.not_valid;
  if (last_frame_[i] >= 0) {
    if (m->device_frame_number > last_frame_[i] + 1) lost_[i] += static_cast<std::uint64_t>(m->device_frame_number - last_frame_[i] - 1);
    if (m->device_frame_number <= last_frame_[i]) ++stats_.repeated;
  }
  if (m->device_frame_number > last_frame_[i]) {
    last_frame_[i] = m->device_frame_number;
    if (i == 0) ++stats_.frames;
  }
  stats_.lcm_gaps = *std::max_element(lost_.begin(), lost_.end());
  if (i == 0) {
    if (last_first_tool_arrival_us_ > 0)
      stats_.max_gap_s = std::max(stats_.max_gap_s, static_cast<double>(arrival - last_first_tool_arrival_us_) * 1e-6);
    last_first_tool_arrival_us_ = arrival;
  }
  if (m->device_time_us > m->publish_time_mono_us) ++stats_.bad_device_time;
  stats_.publish_latency_us.push_back(static_cast<float>(m->publish_time_mono_us - m->device_time_us));
  stats_.arrival_latency_us.push_back(static_cast<float>(arrival - m->device_time_us));
}

void VegaPoseMonitor::on_health(const lcm::ReceiveBuffer*, const std::string&, const device_health_t* m) {
  if (m->device != "ndi") return;
  std::lock_guard lock(mutex_);
  stats_.appliance_dropped_frames = m->dropped_frames;
  stats_.appliance_reconnects = m->reconnects;
  stats_.appliance_frames_total = m->frames_total;
}

VegaStats VegaPoseMonitor::snapshot() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

std::string VegaRun::start(const VegaRunOptions& o) {
  if (appliance_exe().empty()) return "arnav-appliance is not built in this tree";
  if (const std::string why = enter_bench_namespaces(); !why.empty()) return why;
  dir_ = make_temp_dir("arnav-vega");
  const std::string roms = env_or("ARNAV_DATA_DIR", ARNAV_DEFAULT_DATA_DIR) + "/ndi_roms/";
  static const char* kRoms[] = {"8700340.rom", "8700339.rom", "8700248.rom", "8700302.rom", "8700449.rom", "8700340.rom"};
  std::vector<std::pair<std::string, std::string>> tools;
  for (int i = 0; i < std::clamp(o.tools, 1, 6); ++i) tools.push_back({"tool" + std::to_string(i + 1), roms + kRoms[i]});

  std::vector<std::string> sim_argv = {vega_sim_exe(), "--rate", std::to_string(o.rate_hz)};
  for (const auto& [name, rom] : tools) {
    sim_argv.push_back("--tool");
    sim_argv.push_back(name + "=" + rom);
    tool_names_.push_back(name);
  }
  for (const auto& f : o.sim_faults) {
    sim_argv.push_back("--fault");
    sim_argv.push_back(f);
  }
  sim_ = std::make_unique<ChildProcess>(sim_argv, std::vector<std::string>{}, dir_ + "/sim.log", true, o.sim_priority);
  const auto ready = sim_->read_line(30.0);
  if (!ready || ready->rfind("READY ", 0) != 0) throw std::runtime_error("arnav-vega-sim did not get ready:\n" + sim_->log_tail());
  const std::string address = ready->substr(6);  // host:port
  const auto colon = address.rfind(':');

  // A large receive buffer for the subscriber only (2400 poses/s at 400 Hz x 6 tools).
  monitor_ = std::make_unique<VegaPoseMonitor>(std::string(kLcmUrl) + "&recv_buf_size=8388608", tool_names_);
  if (!monitor_->good()) throw std::runtime_error(std::string("cannot open LCM ") + kLcmUrl + " in the bench namespace");
  {
    std::ofstream cfg(dir_ + "/appliance.yaml");
    cfg << "ndi: {host: " << address.substr(0, colon) << ", port: " << address.substr(colon + 1) << "}\nrate_hz: " << o.rate_hz
        << "\nlcm_url: \"" << kLcmUrl << "\"\nrealtime: {cpu_latency_us: " << o.cpu_latency_us << ", priority: " << o.priority
        << "}\ntools:\n";
    for (const auto& [name, rom] : tools) cfg << "  - name: " << name << "\n    rom: " << rom << "\n";
  }
  appliance_ = std::make_unique<ChildProcess>(std::vector<std::string>{appliance_exe(), "--print-health", dir_ + "/appliance.yaml"},
                                              std::vector<std::string>{}, dir_ + "/appliance.log");
  return {};
}

VegaRun::~VegaRun() {
  appliance_.reset();
  sim_.reset();
  monitor_.reset();
  if (!dir_.empty() && std::getenv("ARNAV_HIL_KEEP") == nullptr) fs::remove_all(dir_);
}

int VegaRun::stop_appliance(double timeout_s) { return appliance_ ? appliance_->stop(15, timeout_s) : -1; }
int VegaRun::stop_simulator(double timeout_s) { return sim_ ? sim_->stop(15, timeout_s) : -1; }

std::string VegaRun::logs() const {
  std::string s;
  if (appliance_) s += "--- appliance log ---\n" + appliance_->log_tail(6000) + "\n";
  if (sim_) s += "--- arnav-vega-sim log ---\n" + sim_->log_tail(3000) + "\n";
  return s;
}

}  // namespace arnav::hil
