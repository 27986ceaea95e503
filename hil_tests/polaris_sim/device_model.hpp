#pragma once
// The command interpreter of the simulated Polaris: parses Combined API commands (with or
// without CRC), keeps the device state (baud rate, port handles, loaded ROMs, tracking)
// and encodes the replies a Polaris would send. Pure logic, no I/O: the Simulator moves
// bytes between it and the pseudo-terminal and injects faults. Device time comes from the
// frame counter (frame_number / frame_rate_hz), so ground truth is exact per frame.
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "hil_tests/polaris_sim/reply_encoder.hpp"
#include "hil_tests/polaris_sim/scenario.hpp"

namespace arnav::hil {

// One tool pose as the device knew it when it answered (before wire quantisation).
struct TruthRow {
  std::uint32_t frame_number = 0;
  std::uint8_t handle = 0;
  std::string tool;
  bool valid = false;  // false: reported missing / out of volume
  std::uint32_t port_status = 0;
  Eigen::Isometry3d X_NdiTool = Eigen::Isometry3d::Identity();           // true pose
  Eigen::Isometry3d X_NdiTool_reported = Eigen::Isometry3d::Identity();  // what the device sent (valid rows)
  double rms_error_mm = 0.0;                                             // the reported RMS error field
  bool dropped_out = false;  // missing because the measurement model dropped it this frame
};

class PolarisModel {
 public:
  struct Reply {
    Bytes bytes;
    std::string command;      // the command line it answers (without CRC/CR), for logs
    int baud_after = 0;       // non-zero: switch to this rate once the reply is sent
  };

  explicit PolarisModel(Scenario scenario);

  // Bytes from the host (already past the baud check). Returns the replies, in order.
  std::vector<Reply> receive(std::span<const std::uint8_t> bytes, double now_s);
  // Power-on/break reset: 9600 baud, handles and tracking gone, frame counter restarts.
  // Returns the RESET message the device sends (at 9600).
  Bytes reset(double now_s);

  int baud() const { return baud_; }
  // APIREV answer. "G.001.004" (default) is a Polaris before BX2; an Ethernet Vega answers
  // G.003 or later, which offers BX2 and STREAM (the Vega simulator sets it).
  void set_api_revision(std::string revision) { api_revision_ = std::move(revision); }
  // The tools' data for `frame` as BX2 reports it (Valid/Missing records of enabled
  // handles, frame number, device time = the frame's CLOCK_MONOTONIC instant in ns).
  // Ground truth goes to on_truth. Used for polled BX2 and for streamed frames.
  ndi::TrackingReply bx2_frame(std::uint32_t frame, double now_s);
  // The CLOCK_MONOTONIC instant (s) of frame `frame` on the device clock.
  double frame_time_mono_s(std::uint32_t frame) const;
  void set_baud(int baud) { baud_ = baud; }
  bool tracking() const { return tracking_; }
  std::optional<double> first_tstart_s() const { return first_tstart_s_; }
  // CLOCK_MONOTONIC (s) at now_s = 0: with the scenario's epoch_mono_us the motions run on
  // the world clock (the frame's monotonic time minus the epoch).
  void set_clock_origin_mono_s(double t0_mono_s) { clock_origin_mono_s_ = t0_mono_s; }
  // The time the tools' motions are evaluated at for frame `frame` (s): frame / rate, or,
  // with an epoch, shifted so that path time = the frame's monotonic time - epoch.
  double motion_time_s(std::uint32_t frame) const;
  std::uint32_t frame_at(double now_s) const;
  const Scenario& scenario() const { return scenario_; }

  // Visibility faults: tool hidden / out of volume until the given device time.
  void hide_tool_until(const std::string& tool, double until_s) { missing_until_[tool] = until_s; }
  void push_out_of_volume_until(const std::string& tool, double until_s) { out_of_volume_until_[tool] = until_s; }
  bool knows_tool(const std::string& tool) const;

  // Called for every tool reported in a TX/BX reply.
  std::function<void(const TruthRow&)> on_truth;

  // Ports handed out, for tests and logs.
  struct Port {
    bool initialised = false;
    bool enabled = false;
    std::vector<std::uint8_t> rom;  // 1024 bytes written by PVWR
    std::uint16_t rom_bytes_written = 0;
    int tool_index = -1;            // scenario tool identified at PINIT, -1 none
  };
  const std::map<std::uint8_t, Port>& ports() const { return ports_; }

 private:
  Reply execute(const std::string& line, double now_s);
  Reply reply_tracking(bool binary, const std::string& params, double now_s);
  // One frame's records; include_out_of_volume: report tools outside the volume as Valid.
  ndi::TrackingReply tracking_frame(std::uint32_t frame, double now_s, bool include_out_of_volume);
  int identify_tool(const std::vector<std::uint8_t>& rom, std::uint16_t bytes_written) const;

  Scenario scenario_;
  std::string api_revision_ = "G.001.004";
  std::string input_;
  int baud_ = 9600;
  bool initialised_ = false;
  bool tracking_ = false;
  double boot_s_ = 0.0;
  double clock_origin_mono_s_ = 0.0;
  std::optional<double> first_tstart_s_;
  std::map<std::uint8_t, Port> ports_;
  std::map<std::string, double> missing_until_;
  std::map<std::string, double> out_of_volume_until_;
};

}  // namespace arnav::hil
