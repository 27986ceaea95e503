#pragma once
// arnav-exposure-latency (latency_session.sh, docs/benchmarks.md "Exposure to display"): the
// synthetic camera's timing file (one row per frame it exposed: exposure, rendering, readout
// end, delivery, and what became of the frame; appliance/capture/synthetic_source.hpp)
// joined by sequence number with arnav-host's overlay.csv (published, received, decoded,
// ready, shown) into latency by stage, end to end exposure -> shown, and the frames that
// were never shown, each by its cause:
//   camera, render late   the bench's renderer did not finish before the next frame's
//                         readout (the bench's cost, not the product's)
//   camera, reader late   the appliance did not take the frame before the next one
//   host                  dropped by the host (a newer frame came first) or undecodable
//                         (from the host's --summary-json)
//   lost after delivery   delivered by the camera, never shown nor counted by the host
//                         (the appliance failed the frame, or the bus lost it)
// Absent frames (the camera unplugged) are not exposed and counted apart. Every frame in
// the camera's range must have exactly one timing row (never a silent skip), and every
// shown frame's instants must be in order:
//   exposure <= readout end <= delivered <= published <= received <= decoded <= ready <= shown
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>

#include <nlohmann/json.hpp>

namespace arnav::hil {

struct ExposureLatencyInputs {
  std::filesystem::path timing_csv;   // the synthetic camera's (camera.synthetic.timing)
  std::filesystem::path overlay_csv;  // arnav-host --record DIR/overlay.csv
  std::filesystem::path host_json;    // arnav-host --summary-json (optional: host drop counts)
  double camera_hz = 0.0;
};

// Throws std::runtime_error naming the file and line of a malformed row or a missing file.
nlohmann::json exposure_latency_report(const ExposureLatencyInputs& in);

}  // namespace arnav::hil
