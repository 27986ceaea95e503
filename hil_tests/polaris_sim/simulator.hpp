#pragma once
// The simulated Polaris's event loop: moves bytes between the pseudo-terminal and the
// device, honours the baud rate both ends set (bytes at the wrong rate become noise),
// reacts to serial breaks reported by the test interposer, injects faults (from the
// scenario timeline or the control socket) and records ground truth and events.
#include <atomic>
#include <cstdint>
#include <deque>
#include <fstream>
#include <memory>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "hil_tests/polaris_sim/pty_link.hpp"
#include "hil_tests/polaris_sim/scenario.hpp"
#include "hil_tests/polaris_sim/sim_device.hpp"

namespace arnav::hil {

struct SimulatorOptions {
  std::string pty_link;        // symlink to the pty slave (agreed contract)
  std::string bind_over;       // optional: bind-mount the slave over this node (root, own mount ns)
  std::string break_socket;    // optional: unix datagram socket the interposer reports breaks to
  std::string control_socket;  // optional: unix datagram socket taking fault commands
  std::string truth_csv;       // optional: ground truth per (frame, handle)
  std::string events_jsonl;    // optional: faults and link events, one JSON object a line
  std::string trace;           // optional: the session as an arnav-ndi transcript (replayable)
  double reset_delay_s = 0.3;  // break released -> RESET sent
  bool wire_timing = false;    // pace output at the device baud rate (10 bits a byte)
  std::uint32_t seed = 1;      // for random fault positions
};

class Simulator {
 public:
  Simulator(SimDevice& device, std::vector<TimedFault> timeline, SimulatorOptions options);
  ~Simulator();

  // Creates the port (and sockets); returns the pty slave path.
  std::string start();
  // Serves until `stop` becomes true.
  void run(const std::atomic<bool>& stop);
  // Applies a fault now. Returns an empty string or the reason it cannot be applied.
  std::string inject(const FaultCommand& fault);
  // Ground-truth sink for the model (deduplicated per frame and handle).
  void record_truth(const TruthRow& row);

  struct Stats {
    std::uint64_t commands = 0, replies = 0, bytes_in = 0, bytes_out = 0;
    std::uint64_t noise_bytes_in = 0, noise_bytes_out = 0, breaks = 0, faults = 0;
  };
  const Stats& stats() const { return stats_; }

 private:
  struct Pending {
    double due_s;
    Bytes bytes;
    int baud_after;
    bool last_piece = true;  // a reply sent in chunks counts once
  };
  double now_s() const;
  void event(const std::string& kind, const std::string& detail);
  void on_host_bytes(double now);
  void queue_reply(PolarisModel::Reply reply, double now);
  void flush_output(double now);
  void handle_break_socket(double now);
  void handle_control_socket();
  void run_timeline(double now);
  void send_reset(double now);
  void trace(int kind, const std::string& bytes, std::int64_t value = 0);

  SimDevice& device_;
  std::vector<TimedFault> timeline_;
  std::vector<bool> timeline_done_;
  SimulatorOptions options_;
  PtyLink link_;
  int break_fd_ = -1;
  int control_fd_ = -1;
  double t0_mono_s_ = 0.0;
  std::deque<Pending> output_;
  double wire_free_s_ = 0.0;
  bool in_break_ = false;
  double reset_due_s_ = -1.0;
  double replug_due_s_ = -1.0;
  double chunked_until_s_ = -1.0;
  int drop_next_ = 0, garble_next_ = 0, bad_crc_next_ = 0, garbage_next_ = 0, partial_next_ = 0, slow_next_ = 0;
  double slow_delay_s_ = 0.0;
  std::mt19937 rng_;
  std::ofstream truth_;
  std::ofstream events_;
  std::ofstream trace_;
  int traced_host_baud_ = 0;
  double truth_flushed_s_ = 0.0;
  std::set<std::pair<std::uint32_t, std::uint8_t>> truth_seen_;
  std::uint32_t truth_last_frame_ = 0;
  Stats stats_;
};

}  // namespace arnav::hil
