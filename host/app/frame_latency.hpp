#pragma once
// Latency from exposure to display, by stage (docs/overlay.md, "Latency from exposure to
// display"). Every camera frame the host shows carries six instants on one clock
// (CLOCK_MONOTONIC, us; replay: the log's clock):
//   exposure   image_frame_t.capture_time_mono_us: the source's exposure instant
//              (synthetic camera: the world time of the scene; V4L2: the driver's timestamp)
//   published  image_frame_t.publish_time_mono_us: the appliance, just before publishing
//   received   the host, once the sealed bus has opened the message
//   decoded    the JPEG decoded
//   ready      the overlay composited in memory
//   shown      the window's buffer swap done, or the frame handed to the recorder
// Stages: exposure->published (appliance, with the sensor's readout), transport
// (published->received), decode, render (decoded->ready, with any wait for the rendering
// thread), display (ready->shown), and end to end exposure->shown. "Host processing
// latency" is received->ready (the figure arnav-host-latency-bench has always measured).
// Frames the host never showed count as misses: dropped by the host (a newer frame
// arrived before the rendering thread took it), undecodable, or never received (gaps in
// the camera's sequence numbers: dropped by the camera or the appliance, lost on the bus,
// or a camera outage).
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace arnav::host {

struct FrameStamps {
  std::int64_t sequence = 0;
  std::int64_t exposure_us = 0;
  std::int64_t published_us = 0;
  std::int64_t received_us = 0;
  std::int64_t decoded_us = 0;
  std::int64_t ready_us = 0;
  std::int64_t shown_us = 0;
};

// "" when exposure <= published <= received <= decoded <= ready <= shown; otherwise names
// the first pair out of order and by how much (a clock that is not shared, a bad stamp).
std::string stamp_order_error(const FrameStamps& s);

struct Quantiles {
  std::size_t n = 0;
  double p50 = 0, p99 = 0, p999 = 0, max = 0;
};
// Nearest rank (q (n-1), rounded); all zero for no values.
Quantiles quantiles(std::vector<double> v);
// The q-quantile when `misses` more values are infinitely late: nullopt when it falls on one.
std::optional<double> quantile_with_misses(std::vector<double> v, std::int64_t misses, double q);
nlohmann::json to_json(const Quantiles& q);

class FrameLatency {
 public:
  // A frame received (before decoding): gaps in the sequence numbers are frames never received.
  void received(std::int64_t sequence);
  // A frame shown, with its instants.
  void shown(const FrameStamps& s);
  void dropped_by_host() { ++dropped_by_host_; }
  void undecodable() { ++undecodable_; }

  std::int64_t frames_shown() const { return static_cast<std::int64_t>(e2e_ms_.size()); }
  std::int64_t misses() const { return dropped_by_host_ + undecodable_ + not_received_; }
  std::int64_t out_of_order() const { return out_of_order_; }
  // Stages (p50/p99/p99.9/max, ms), end to end with misses, miss counts, stamp-order violations.
  nlohmann::json json() const;
  // "exposure-to-display: p50 P ms, p99 Q ms, p99.9 R ms (N frames shown, M missed)".
  std::string summary_line() const;

 private:
  std::int64_t last_received_ = -1;
  std::int64_t not_received_ = 0, dropped_by_host_ = 0, undecodable_ = 0, out_of_order_ = 0;
  std::string first_order_error_;
  std::vector<double> appliance_ms_, transport_ms_, decode_ms_, render_ms_, display_ms_, e2e_ms_, host_ms_, processing_ms_;
};

}  // namespace arnav::host
