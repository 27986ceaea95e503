#include "hil_tests/bench/lcm_capture.hpp"

#include <chrono>

#include "protocol/channels.hpp"
#include "protocol/clock.hpp"

namespace arnav::hil {

LcmCapture::LcmCapture(const std::string& url, const seal::BusSecurity& security) : bus_(url, security) {
  good_ = bus_.good();
  if (!good_) return;
  bus_.subscribe(std::string(channels::kPoseRegex), &LcmCapture::on_pose, this);
  bus_.subscribe(std::string(channels::kHealthRegex), &LcmCapture::on_health, this);
  bus_.subscribe(std::string(channels::kEvents), &LcmCapture::on_event, this);
  bus_.subscribe(std::string(channels::kCloudPrefix) + ".*", &LcmCapture::on_cloud, this);
  thread_ = std::thread([this] {
    while (!stop_.load()) bus_.handleTimeout(50);
  });
}

LcmCapture::~LcmCapture() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
}

void LcmCapture::on_pose(const lcm::ReceiveBuffer*, const std::string&, const tool_pose_t* m) {
  std::lock_guard lock(mutex_);
  poses_.push_back({*m, monotonic_us()});
}
void LcmCapture::on_health(const lcm::ReceiveBuffer*, const std::string&, const device_health_t* m) {
  std::lock_guard lock(mutex_);
  health_.push_back({*m, monotonic_us()});
}
void LcmCapture::on_event(const lcm::ReceiveBuffer*, const std::string&, const appliance_event_t* m) {
  std::lock_guard lock(mutex_);
  events_.push_back({*m, monotonic_us()});
}

void LcmCapture::on_cloud(const lcm::ReceiveBuffer*, const std::string&, const point_cloud_t* m) {
  std::lock_guard lock(mutex_);
  clouds_.push_back({*m, monotonic_us()});
}
std::vector<Received<point_cloud_t>> LcmCapture::clouds() const {
  std::lock_guard lock(mutex_);
  return clouds_;
}

std::vector<Received<tool_pose_t>> LcmCapture::poses() const {
  std::lock_guard lock(mutex_);
  return poses_;
}
std::vector<Received<device_health_t>> LcmCapture::health() const {
  std::lock_guard lock(mutex_);
  return health_;
}
std::vector<Received<appliance_event_t>> LcmCapture::events() const {
  std::lock_guard lock(mutex_);
  return events_;
}

bool LcmCapture::wait_for(const std::function<bool(const LcmCapture&)>& pred, double timeout_s) const {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (!pred(*this)) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return true;
}

std::size_t LcmCapture::valid_after(const std::string& tool, std::int64_t after_us) const {
  std::lock_guard lock(mutex_);
  std::size_t n = 0;
  for (const auto& p : poses_)
    if (p.arrival_us > after_us && p.msg.tool_name == tool && p.msg.status == tool_pose_t::STATUS_VALID) ++n;
  return n;
}

std::optional<std::int64_t> LcmCapture::first_valid_after(const std::string& tool, std::int64_t after_us) const {
  std::lock_guard lock(mutex_);
  for (const auto& p : poses_)
    if (p.arrival_us > after_us && p.msg.tool_name == tool && p.msg.status == tool_pose_t::STATUS_VALID) return p.arrival_us;
  return std::nullopt;
}

std::size_t LcmCapture::events_after(const std::string& code, std::int64_t after_us) const {
  std::lock_guard lock(mutex_);
  std::size_t n = 0;
  for (const auto& e : events_)
    if (e.arrival_us > after_us && e.msg.code == code) ++n;
  return n;
}

std::string LcmCapture::event_log() const {
  std::lock_guard lock(mutex_);
  std::string s;
  for (const auto& e : events_) s += std::to_string(e.arrival_us) + " " + e.msg.code + ": " + e.msg.text + "\n";
  return s;
}

}  // namespace arnav::hil
