#pragma once
// NDI Polaris session state machine over a Transport: contact (break-reset, or INIT
// probing across baud rates when no RESET comes, e.g. on a pty), COMM negotiation with
// fallback to lower rates, stale-handle cleanup, ROM loading (PHRQ + PVWR), PINIT, PENA,
// TSTART, BX polling with TX fallback, and recovery from timeouts, corrupt frames,
// device resets and a vanished port. Single-threaded: the owner calls start() until it
// returns true, then poll() in a loop; after a fault poll() leaves the session in
// Recovering and the owner calls start() again (it reopens the port if needed).
#include <array>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "appliance/ndi/frame_reader.hpp"
#include "appliance/ndi/reply.hpp"
#include "appliance/ndi/rom.hpp"
#include "appliance/ndi/tracking.hpp"
#include "appliance/serial/transport.hpp"

namespace arnav::ndi {

struct ToolConfig {
  std::string name;                // e.g. "pointer"; the LCM channel is ARNAV_POSE_<name>
  std::filesystem::path rom_path;  // NDI .rom file
};

struct SessionConfig {
  std::vector<ToolConfig> tools;
  int target_baud = 115200;  // COMM target; lower rates are tried when it fails
  bool use_bx = true;        // false: TX only
  // Firmware (VER:0 text) containing any of these substrings is polled with TX.
  std::vector<std::string> tx_firmware;
  int bx_failures_before_tx = 5;      // consecutive corrupt/unparsable BX replies
  int timeouts_before_recovery = 3;   // consecutive poll timeouts
  int bad_replies_before_recovery = 10;  // consecutive corrupt replies once on TX
  std::chrono::milliseconds setup_timeout{5000};    // bring-up commands (PINIT is slow)
  std::chrono::milliseconds probe_timeout{400};     // INIT probe per baud rate
  std::chrono::milliseconds tracking_timeout{150};  // BX/TX replies
  std::chrono::milliseconds break_duration{300};
  std::chrono::milliseconds reset_wait{3000};       // RESET after a break
  std::chrono::milliseconds comm_settle{100};       // after COMM's OKAY, before switching
  int pvwr_retries = 3;
  // Network links (TCP) with API revision G.003+: the device pushes BX2 frames after
  // `STREAM --id=<stream_id> BX2 --6d=tools`; false: BX2 is polled. Older API revisions
  // are polled with BX.
  bool stream = true;
  std::string stream_id = "ARNAV";
};

enum class ReplyMode : std::uint8_t { Bx, Tx, Bx2, StreamedBx2 };
std::string_view to_string(ReplyMode m);

enum class LinkState : std::uint8_t { Down, Connecting, Initialising, Tracking, Recovering };
std::string_view to_string(LinkState s);

enum class Severity : std::uint8_t { Info, Warning, Error };

struct Event {
  Severity severity = Severity::Info;
  std::string_view code;  // stable: NDI_* (docs/appliance.md)
  std::string text;       // names port, tool, rate, code as relevant
};

struct SessionCounters {
  std::int64_t frames_total = 0;
  std::int64_t crc_errors = 0;
  std::int64_t timeouts = 0;
  std::int64_t resyncs = 0;
  std::int64_t garbage_bytes = 0;
  std::int64_t error_replies = 0;
  std::int64_t resets = 0;
  std::int64_t reconnects = 0;
  std::int64_t dropped_frames = 0;
  std::int64_t bad_replies = 0;  // CRC-good replies that did not parse
  std::int64_t stray_stream_packets = 0;  // stream packets with another id, or while a command waited
};

struct LoadedTool {
  ToolConfig config;
  ToolRom rom;
  std::uint8_t handle = 0;  // valid while tracking
  PortHandleInfo info;      // PHINF basic
};

enum class PollResult : std::uint8_t { NewFrame, SameFrame, Failed };

// What `arnav-ndi probe` reports.
struct ProbeResult {
  int baud = 9600;
  std::string firmware, serial_number;
  std::vector<std::string> version_lines;
  struct Handle {
    std::uint8_t handle = 0;
    std::uint16_t status = 0;  // PHSR status bits
    PortHandleInfo info;       // PHINF basic, when the device answered
    bool has_info = false;
  };
  std::vector<Handle> handles;
};

class Session {
 public:
  using EventSink = std::function<void(const Event&)>;

  // Reads and checks every ROM first: throws RomError naming the file before any traffic.
  Session(SessionConfig config, TransportFactory open_port, EventSink on_event);
  ~Session();
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;

  // Opens the port if needed and brings the device up to tracking. false on failure
  // (events say why); call again later. Throws nothing for device or port faults.
  bool start();
  // One BX (or TX) round trip. NewFrame fills out and the monotonic time (us) at which
  // the last byte of the reply was read. On repeated faults the state becomes Recovering.
  PollResult poll(TrackingReply& out, std::int64_t& receive_mono_us);
  // TSTOP, COMM back to 9600, close the port. Best effort; never throws.
  void stop();
  // Contact, COMM, VER:0, PHSR:00 and PHINF for each handle, without loading tools or
  // tracking; then stop(). false (detail() says why) when the device cannot be reached.
  bool probe(ProbeResult& out);

  // While *flag is non-zero, start() and poll() give up at once (every wait ends as a
  // timeout), so a signal handler that sets it gets a prompt shutdown; stop() still talks
  // to the device. The flag must outlive the session.
  void set_cancel_flag(const volatile std::sig_atomic_t* flag) { cancel_ = flag; }

  // Called about every 100 ms while start() waits for the device (bring-up and recovery
  // can take seconds), so the owner can keep publishing health. Same thread; the callback
  // may read the session's const accessors but must not call start/poll/stop.
  void set_idle_callback(std::function<void()> idle) { idle_ = std::move(idle); }

  LinkState state() const { return state_; }
  SessionCounters counters() const;
  int baud() const { return baud_; }
  bool using_bx() const { return use_bx_; }
  ReplyMode reply_mode() const;
  // The device pushes frames: poll() only waits for the next one (no pacing by the owner).
  bool streaming() const { return streaming_; }
  // API revision major number (APIREV "G.003.005" -> 3); 0 when not asked (serial links).
  int api_major() const { return api_major_; }
  const std::string& firmware() const { return firmware_; }
  const std::string& serial_number() const { return serial_; }
  const std::string& port_name() const { return port_name_; }
  const std::string& detail() const { return detail_; }
  const std::vector<LoadedTool>& tools() const { return tools_; }
  // Index into tools() for a handle, or -1.
  int tool_index(std::uint8_t handle) const;

 private:
  enum class Outcome : std::uint8_t { Reply, Corrupt, Timeout };
  struct CmdResult {
    enum Status : std::uint8_t { Ok, Error, Timeout, Corrupt, Reset } status = Timeout;
    std::string body;
    std::uint8_t error_code = 0;
  };

  Outcome transact(std::string_view command_bytes, std::chrono::milliseconds timeout, bool expect_binary, Frame& frame);
  CmdResult command(std::string_view name, std::string_view params, std::chrono::milliseconds timeout,
                    bool count_timeout = true);
  bool expect_ok(std::string_view name, std::string_view params, std::chrono::milliseconds timeout, CmdResult* out = nullptr);

  void open_port();
  void close_port();
  bool bring_up();
  bool establish_contact();
  bool wait_for_reset();
  bool probe_init(int baud);
  bool init_device();
  bool negotiate_baud();
  bool read_version();
  bool contact_network();
  bool choose_network_mode();
  bool start_stream();
  Outcome read_stream_frame(Frame& frame);
  PollResult finish_frame(TrackingReply& out);
  void free_stale_handles();
  bool load_tool(LoadedTool& tool);
  void fail_bring_up(const std::string& why);

  // The last poll before a recovery: true when the device answered it (frame, outcome set).
  bool last_chance_poll(std::string_view mode, Frame& frame, Outcome& outcome);
  void begin_recovery(std::string_view code, const std::string& why);
  void emit(Severity s, std::string_view code, std::string text);
  void set_baud(int baud);

  SessionConfig config_;
  TransportFactory open_port_;
  EventSink on_event_;
  std::unique_ptr<Transport> transport_;
  FrameReader reader_;
  std::array<std::uint8_t, 4096> read_buf_{};
  std::int64_t last_read_mono_us_ = 0;

  std::vector<LoadedTool> tools_;
  std::vector<std::uint8_t> previous_handles_;
  std::set<int> failed_bauds_;
  LinkState state_ = LinkState::Down;
  bool ever_opened_ = false;
  bool use_bx_ = true;
  bool bx_unreliable_ = false;  // BX fell back to TX once: stay on TX after recoveries
  int baud_ = 9600;
  std::string firmware_, serial_, port_name_, detail_;
  std::vector<std::string> version_lines_;
  std::string bx_command_, tx_command_, bx2_command_;
  bool use_bx2_ = false;
  bool streaming_ = false;
  bool stream_wanted_ = false;
  int api_major_ = 0;

  SessionCounters counters_;
  int consecutive_timeouts_ = 0;
  int consecutive_bad_ = 0;
  bool have_last_frame_ = false;
  std::uint32_t last_frame_ = 0;
  std::uint16_t last_system_status_ = 0;
  std::int64_t recovery_started_us_ = 0;
  const volatile std::sig_atomic_t* cancel_ = nullptr;
  std::function<void()> idle_;
  bool stopping_ = false;
};

}  // namespace arnav::ndi
