#pragma once
// The simulated Polaris Vega: the Polaris command interpreter (PolarisModel, API revision
// G.003+) served over TCP as an Ethernet tracker is, plus the streaming an Ethernet NDI
// device offers: after `STREAM --id=ID BX2 --6d=tools` every frame is pushed as a stream
// packet (D4 B5, id, header CRC, BX2 reply) at the frame clock, which runs on
// CLOCK_MONOTONIC whatever the host does: frames due during a stall go out after it, so
// loss is measurable on the host. The frame's device timestamp is its CLOCK_MONOTONIC
// instant, so a host on the same machine can measure device time -> publish latency.
// TCP faults: connection reset, stall, corrupt CRC, split writes, missing and duplicate
// frame numbers, stream packets racing USTREAM's OKAY. One client at a time (a new
// connection replaces the old one, as after a host restart); the device keeps tracking
// when a connection drops, its stream does not survive. Binds 127.0.0.1 unless told.
#include <atomic>
#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <vector>

#include "hil_tests/polaris_sim/device_model.hpp"

namespace arnav::hil {

struct VegaFault {
  enum class Kind { kReset, kStall, kBadCrc, kSplit, kSkip, kDuplicate };
  double at_s = 0.0;       // seconds after the first STREAM (or first TSTART when never streamed)
  Kind kind = Kind::kReset;
  double seconds = 0.0;    // stall
  int count = 1;           // bad_crc, split, skip, duplicate
  std::string text;
};

// "AT_S:KIND [ARG]": reset | stall S | bad_crc [N] | split [N] | skip [N] | duplicate [N].
// Throws ScenarioError naming the spec.
VegaFault parse_vega_fault(const std::string& spec);

struct VegaOptions {
  std::string bind_address = "127.0.0.1";
  int port = 0;                          // 0: any free port (printed in READY)
  std::string api_revision = "G.003.005";
  bool stream_supported = true;          // false: STREAM answers ERROR01 (polled BX2 only)
  int ustream_race_packets = 2;          // stream packets sent after USTREAM, before its OKAY
};

class VegaServer {
 public:
  VegaServer(PolarisModel& model, VegaOptions options, std::vector<VegaFault> faults);
  ~VegaServer();
  VegaServer(const VegaServer&) = delete;
  VegaServer& operator=(const VegaServer&) = delete;

  // Binds and listens; returns the TCP port. Throws std::runtime_error naming address:port.
  int start();
  // Serves until stop becomes true.
  void run(const std::atomic<bool>& stop);

  struct Stats {
    std::uint64_t connections = 0, commands = 0, stream_packets = 0, frames_skipped = 0, resets = 0, faults = 0;
  };
  // Read after run() returned (or from the thread that runs it).
  const Stats& stats() const { return stats_; }
  // How late each streamed frame was handed to the kernel after its device timestamp (us):
  // the simulator's own share of a device time -> published latency (a real device sends
  // on its own clock). Read after run() returned.
  const std::vector<float>& send_lateness_us() const { return send_lateness_us_; }

 private:
  struct Pending {
    double due_s;
    Bytes bytes;
    double frame_time_s = -1.0;  // a frame's last piece: its device time (s since start)
  };
  double now_s() const;
  void accept_client();
  void close_client(bool reset);
  void on_client_bytes(double now);
  void handle_line(const std::string& line, double now);
  void handle_stream(const std::string& params, double now);
  void handle_ustream(const std::string& params, double now);
  void send_due_frames(double now);
  void emit_frame(std::uint32_t frame, double now);
  void queue(Bytes bytes, double now, double frame_time_s = -1.0);
  void flush(double now);
  void run_timeline(double now);
  double next_wakeup_s(double now) const;

  PolarisModel& model_;
  VegaOptions options_;
  std::vector<VegaFault> faults_;
  std::vector<bool> fault_done_;
  int listen_fd_ = -1;
  int client_fd_ = -1;
  double t0_mono_s_ = 0.0;
  std::string input_;
  std::deque<Pending> output_;
  bool streaming_ = false;
  std::string stream_id_;
  std::uint32_t next_frame_ = 0;
  std::optional<double> timeline_start_s_;
  double stall_until_s_ = -1.0;
  int bad_crc_left_ = 0, split_left_ = 0, duplicate_left_ = 0;
  Stats stats_;
  std::vector<float> send_lateness_us_;
};

}  // namespace arnav::hil
