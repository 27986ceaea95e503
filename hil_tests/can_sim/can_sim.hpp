#pragma once
// arnav-can-sim: simulated CAN devices (foot pedal, instrument buttons) for the HIL bench,
// reaching the appliance through either production path (docs/can.md):
// - slcan: a Lawicel adapter on a pseudo-terminal (bind-mounted over a real tty node in the
//   bench's mount namespace, like the simulated Polaris), answering C/O/S/V/N/F and frames;
// - SocketCAN: a bus served on DIR/IFACE.sock (SOCK_SEQPACKET, one struct can_frame per
//   datagram) that the test-only can_shim connects a production CAN socket to.
// The devices come from the appliance configuration's `can:` section: heartbeat devices
// send 0x700+id every heartbeat period, periodic devices their frame every periodic period
// (carrying the inputs it holds), input frames go out on every change.
// Commands (scenario steps, control socket) are listed in commands_help().
#include <cstdint>
#include <functional>
#include <map>
#include <queue>
#include <random>
#include <string>
#include <vector>

#include "appliance/can/can_config.hpp"
#include "appliance/can/can_frame.hpp"

namespace arnav::hil {

struct CanSimOptions {
  std::string socketcan_dir;   // SocketCAN mode: serve DIR/IFACE.sock
  std::string interface = "vcan0";
  std::string pty_link;        // slcan mode: symlink to the pty slave
  std::string bind_over;       // slcan mode: bind-mount the slave over this node
  std::string control_socket;  // unix datagram socket for commands
  std::string log_path;        // candump log of every frame the simulated devices sent
  int heartbeat_period_ms = 100;
  int periodic_period_ms = 20;
  unsigned seed = 1;
};

struct ScenarioStep {
  double at_s = 0.0;
  std::string command;
};

// Scenario YAML: {steps: [{at_s: 1.5, do: "press pedal_cut"}, ...]}. Throws
// std::runtime_error naming file:line.
std::vector<ScenarioStep> load_can_scenario(const std::string& path);
std::string commands_help();

class CanSim {
 public:
  CanSim(CanSimOptions options, can::CanConfig config);
  ~CanSim();
  // Creates the bus or the pty; returns the READY line's argument (socket or slave path).
  std::string start();
  // Checks and runs (or schedules) a command; "OK" or "ERROR <why>". dry_run: check only.
  std::string command(const std::string& text, bool dry_run = false);
  void schedule(double at_s_from_start, const std::string& command);
  // Steps at epoch_mono_us + at_s instead (the bench's world clock shared with the simulated
  // Polaris and the synthetic camera, docs/hil.md); a step already past runs at once.
  void schedule_from_epoch(std::int64_t epoch_mono_us, double at_s, const std::string& command);
  // Serves until stop is set.
  void run(const volatile bool& stop);
  // Frames sent so far (data and error), for tests.
  std::int64_t frames_sent() const { return frames_sent_; }

 private:
  struct Action {
    std::int64_t at_us;
    std::uint64_t seq;
    std::function<void()> fn;
    bool operator>(const Action& o) const { return at_us != o.at_us ? at_us > o.at_us : seq > o.seq; }
  };
  void at(std::int64_t t_us, std::function<void()> fn);
  void send(const can::CanFrame& f);
  void send_error(std::uint32_t cls, std::uint8_t crtl);
  void send_image(std::uint32_t id, bool ext);
  void set_input(std::size_t i, bool pressed, double value);
  void heartbeat_tick();
  void periodic_tick();
  void slcan_from_host(const char* data, std::size_t n);
  void slcan_line(const std::string& line);
  void to_host(const std::string& bytes);
  void accept_clients();
  void read_clients();
  void handle_control();
  bool bus_off() const;
  std::size_t input_index(const std::string& name) const;
  std::size_t node_index(const std::string& name) const;

  CanSimOptions o_;
  can::CanConfig cfg_;
  std::mt19937 rng_;
  std::int64_t start_us_ = 0;
  std::uint64_t seq_ = 0;
  std::priority_queue<Action, std::vector<Action>, std::greater<Action>> actions_;
  std::map<std::pair<std::uint32_t, bool>, can::CanFrame> images_;
  std::vector<bool> node_on_, heartbeat_on_;
  std::vector<bool> pressed_;
  std::int64_t bus_off_until_us_ = 0;
  std::uint8_t slcan_flags_ = 0;
  int drop_chars_ = 0;
  // SocketCAN bus
  int listen_fd_ = -1;
  std::vector<int> clients_;
  // slcan
  struct PtyState;
  std::unique_ptr<PtyState> pty_;
  bool slcan_open_ = false;
  int slcan_bitrate_ = -1;
  std::string host_line_;
  std::string out_;
  int control_fd_ = -1;
  std::FILE* log_ = nullptr;
  std::int64_t frames_sent_ = 0;
};

}  // namespace arnav::hil
