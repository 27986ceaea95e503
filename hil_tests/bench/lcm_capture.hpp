#pragma once
// Records what the appliance publishes (poses, health, events) with the arrival time on
// the test's monotonic clock, from a background LCM thread. Queries take a snapshot.
#include <atomic>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <lcm/lcm-cpp.hpp>

#include "arnav/appliance_event_t.hpp"
#include "arnav/device_health_t.hpp"
#include "arnav/point_cloud_t.hpp"
#include "arnav/tool_pose_t.hpp"
#include "protocol/seal/sealed_lcm.hpp"

namespace arnav::hil {

template <typename T>
struct Received {
  T msg;
  std::int64_t arrival_us;
};

class LcmCapture {
 public:
  // security: the bus key when the appliance seals (docs/protocol.md), off otherwise.
  explicit LcmCapture(const std::string& url, const seal::BusSecurity& security = seal::BusSecurity::off());
  ~LcmCapture();
  bool good() const { return good_; }

  std::vector<Received<tool_pose_t>> poses() const;
  std::vector<Received<device_health_t>> health() const;
  std::vector<Received<appliance_event_t>> events() const;
  std::vector<Received<point_cloud_t>> clouds() const;  // ARNAV_CLOUD_* (the pointer swab)

  // Waits until pred(*this) holds or timeout; returns whether it held.
  bool wait_for(const std::function<bool(const LcmCapture&)>& pred, double timeout_s) const;
  // Valid poses of `tool` that arrived after `after_us`.
  std::size_t valid_after(const std::string& tool, std::int64_t after_us) const;
  // First arrival of a valid pose of `tool` after `after_us`.
  std::optional<std::int64_t> first_valid_after(const std::string& tool, std::int64_t after_us) const;
  // Events with this code that arrived after `after_us`.
  std::size_t events_after(const std::string& code, std::int64_t after_us) const;
  std::string event_log() const;  // for failure messages

 private:
  void on_pose(const lcm::ReceiveBuffer*, const std::string&, const tool_pose_t* m);
  void on_health(const lcm::ReceiveBuffer*, const std::string&, const device_health_t* m);
  void on_event(const lcm::ReceiveBuffer*, const std::string&, const appliance_event_t* m);
  void on_cloud(const lcm::ReceiveBuffer*, const std::string&, const point_cloud_t* m);

  seal::SealedLcm bus_;
  bool good_ = false;
  std::atomic<bool> stop_{false};
  mutable std::mutex mutex_;
  std::vector<Received<tool_pose_t>> poses_;
  std::vector<Received<device_health_t>> health_;
  std::vector<Received<point_cloud_t>> clouds_;
  std::vector<Received<appliance_event_t>> events_;
  std::thread thread_;
};

}  // namespace arnav::hil
