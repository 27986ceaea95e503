#pragma once
// The appliance's CAN path (docs/can.md), built only when the configuration has `can:`.
// CanService does the work one step at a time (open the bus, read a frame, run the
// decoder's deadlines, publish health) and publishes over the LCM it is given:
//   input_event_t      ARNAV_INPUT        one per press / release (forced ones included)
//   input_event_t      ARNAV_INPUT_STATE  every input's state at health_rate_hz (CAUSE_STATE)
//   device_health_t    ARNAV_HEALTH_can   at health_rate_hz
//   appliance_event_t  ARNAV_EVENT        source "can": bus and device changes, faults
// CanRuntime runs a CanService on its own thread with its own LCM.
// A kernel without AF_CAN is said once (event CAN_UNAVAILABLE + health) and the service
// keeps publishing health; an interface or port that is missing is retried each second.
#include <atomic>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <thread>

#include <lcm/lcm-cpp.hpp>

#include "protocol/seal/sealed_lcm.hpp"

#include "appliance/realtime/latency_stats.hpp"
#include "appliance/can/can_config.hpp"
#include "appliance/can/can_transport.hpp"
#include "appliance/can/input_decoder.hpp"
#include "arnav/appliance_event_t.hpp"
#include "arnav/device_health_t.hpp"
#include "arnav/input_event_t.hpp"

namespace arnav::can {

using TransportFactory = std::function<std::unique_ptr<CanTransport>()>;

// The production transport for a configuration: SocketCAN, or slcan over libserialport
// (a tty libserialport does not list, such as a pty, through termios). Throws CanUnavailable.
std::unique_ptr<CanTransport> open_transport(const CanConfig& config);

class CanService final : private DecoderSink {
 public:
  CanService(CanConfig config, seal::SealedLcm& lcm, TransportFactory factory, double health_rate_hz = 1.0);
  ~CanService() override;

  // One step: waits at most max_wait for a frame or a deadline.
  void step(std::chrono::microseconds max_wait);
  // Releases every pressed input (CAUSE_LINK_LOST), closes the bus, publishes health.
  void shutdown();

  const InputDecoder& decoder() const { return decoder_; }
  bool open() const { return transport_ != nullptr; }
  device_health_t health() const;  // what publish_health would send now (no window reset)
  std::int64_t events_published() const { return event_sequence_; }
  // Called (on the CAN thread) with each input change after it is published: the
  // appliance's pointer swab follows its input this way (appliance/app/swab).
  void set_input_listener(std::function<void(const std::string& input, bool pressed)> listener) { input_listener_ = std::move(listener); }
  // An appliance_event_t from the CAN path (source "can").
  void event(std::int8_t severity, const std::string& code, const std::string& text);

 private:
  void on_input(const InputChange& c) override;
  void on_node(const NodeChange& c) override;
  void on_bus(const BusChange& c) override;
  void try_open(std::int64_t now);
  void publish_health(std::int64_t now);
  device_health_t fill_health(const app::LatencySummary& l, double rate) const;

  CanConfig config_;
  seal::SealedLcm& lcm_;
  TransportFactory factory_;
  InputDecoder decoder_;
  std::unique_ptr<CanTransport> transport_;
  TransportCounters closed_counters_;  // counters of transports closed earlier
  std::string health_channel_;
  std::int64_t health_period_us_;
  std::int64_t next_health_us_ = 0;
  std::int64_t next_open_us_ = 0;
  std::int64_t window_start_us_ = 0, frames_at_window_ = 0;
  bool unavailable_forever_ = false;  // no AF_CAN
  bool open_failure_reported_ = false;
  bool ever_open_ = false;
  bool closing_ = false;
  std::string last_fault_;
  std::int64_t reconnects_ = 0;
  std::int64_t event_sequence_ = 0;
  std::int64_t input_sequence_ = 0;
  app::LatencyWindow latency_;
  std::function<void(const std::string&, bool)> input_listener_;
  input_event_t msg_{};
  Received rx_;
};

class CanRuntime {
 public:
  // nullptr when the configuration has no `can:`; throws CanConfigError.
  static std::unique_ptr<CanRuntime> load(const std::filesystem::path& config_file);
  explicit CanRuntime(CanConfig config) : config_(std::move(config)) {}
  ~CanRuntime();

  const CanConfig& config() const { return config_; }
  std::string summary() const;
  // Opens LCM (throws CanConfigError naming lcm_url) and starts the thread.
  void start(const std::string& lcm_url, const seal::BusSecurity& security, double health_rate_hz = 1.0);
  // Set before start(): told every input change (the CAN thread calls it).
  void set_input_listener(std::function<void(const std::string& input, bool pressed)> listener) { input_listener_ = std::move(listener); }
  void stop();

 private:
  CanConfig config_;
  std::unique_ptr<seal::SealedLcm> lcm_;
  std::unique_ptr<CanService> service_;
  std::function<void(const std::string&, bool)> input_listener_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace arnav::can
