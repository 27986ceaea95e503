#include "appliance/ndi/session.hpp"

#include <algorithm>
#include <thread>

#include "appliance/ndi/bx.hpp"
#include "appliance/ndi/bx2.hpp"
#include "appliance/ndi/command.hpp"
#include "appliance/ndi/error_codes.hpp"
#include "protocol/clock.hpp"

namespace arnav::ndi {
namespace {

// Rates the device knows, fastest first (COMM codes 0-7 and A).
constexpr std::array<int, 9> kDeviceBauds = {1228739, 921600, 230400, 115200, 57600, 38400, 19200, 14400, 9600};

std::string error_text(std::uint8_t code) {
  const auto info = error_code_info(code);
  return "ERROR" + hex2(code) + " " + std::string(info.symbol) + " (" + std::string(info.description) + ")";
}

}  // namespace

std::string_view to_string(LinkState s) {
  switch (s) {
    case LinkState::Down: return "down";
    case LinkState::Connecting: return "connecting";
    case LinkState::Initialising: return "initialising";
    case LinkState::Tracking: return "tracking";
    case LinkState::Recovering: return "recovering";
  }
  return "?";
}

std::string_view to_string(ReplyMode m) {
  switch (m) {
    case ReplyMode::Bx: return "BX";
    case ReplyMode::Tx: return "TX";
    case ReplyMode::Bx2: return "BX2";
    case ReplyMode::StreamedBx2: return "streamed BX2";
  }
  return "?";
}

ReplyMode Session::reply_mode() const {
  if (streaming_) return ReplyMode::StreamedBx2;
  if (use_bx2_) return ReplyMode::Bx2;
  return use_bx_ ? ReplyMode::Bx : ReplyMode::Tx;
}

Session::Session(SessionConfig config, TransportFactory open_port, EventSink on_event)
    : config_(std::move(config)), open_port_(std::move(open_port)), on_event_(std::move(on_event)) {
  // Every ROM is read and checked before any serial traffic.
  for (const auto& t : config_.tools) tools_.push_back(LoadedTool{t, load_rom(t.rom_path), 0, {}});
  if (!baud_code(config_.target_baud))
    throw PortError("baud " + std::to_string(config_.target_baud) + " is not a rate the NDI COMM command supports");
  use_bx_ = config_.use_bx;
  bx_command_ = encode_command("BX", "0801");  // transforms + tools outside the volume
  tx_command_ = encode_command("TX", "0801");
  bx2_command_ = encode_command("BX2", "--6d=tools");
}

Session::~Session() = default;

SessionCounters Session::counters() const {
  SessionCounters c = counters_;
  c.crc_errors = reader_.counters().crc_errors;
  c.resyncs = reader_.counters().resyncs;
  c.garbage_bytes = reader_.counters().garbage_bytes;
  return c;
}

int Session::tool_index(std::uint8_t handle) const {
  for (std::size_t i = 0; i < tools_.size(); ++i)
    if (tools_[i].handle == handle) return static_cast<int>(i);
  return -1;
}

void Session::emit(Severity s, std::string_view code, std::string text) {
  if (s != Severity::Info) detail_ = std::string(code) + ": " + text;
  if (on_event_) on_event_(Event{s, code, std::move(text)});
}

void Session::set_baud(int baud) {
  transport_->set_baud(baud);
  baud_ = baud;
}

// ---- one exchange ---------------------------------------------------------------------

Session::Outcome Session::transact(std::string_view command_bytes, std::chrono::milliseconds timeout,
                                   bool expect_binary, Frame& frame) {
  // A reply that arrived after its command timed out must not answer this command.
  if (reader_.buffered() > 0) reader_.clear();
  reader_.set_expect_binary(expect_binary);
  if (!command_bytes.empty())
    transport_->write(std::span(reinterpret_cast<const std::uint8_t*>(command_bytes.data()), command_bytes.size()));
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    // Stream packets are the stream's, never a command's reply (e.g. after USTREAM).
    bool got = false;
    while ((got = reader_.next(frame)) && frame.streamed()) ++counters_.stray_stream_packets;
    if (got) return frame.crc_ok ? Outcome::Reply : Outcome::Corrupt;
    if (cancel_ && *cancel_ && !stopping_) {
      reader_.clear();
      return Outcome::Timeout;
    }
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) {
      reader_.clear();
      return Outcome::Timeout;
    }
    std::chrono::milliseconds wait = left;
    if (idle_ && state_ != LinkState::Tracking) {
      idle_();
      wait = std::min(wait, std::chrono::milliseconds(100));
    }
    const std::size_t n = transport_->read(read_buf_, wait);
    if (n > 0) {
      last_read_mono_us_ = monotonic_us();
      reader_.feed(std::span(read_buf_.data(), n));
    }
  }
}

Session::CmdResult Session::command(std::string_view name, std::string_view params, std::chrono::milliseconds timeout,
                                    bool count_timeout) {
  // count_timeout = false while probing, where silence and errors are expected.
  CmdResult r;
  Frame frame;
  const std::string bytes = encode_command(name, params);
  // A reply damaged on the wire is asked for again, except where repeating the command
  // changes the device state (COMM switches rate, PHRQ allocates a handle).
  const int attempts = (name == "COMM" || name == "PHRQ") ? 1 : 3;
  Outcome outcome = Outcome::Timeout;
  for (int attempt = 0; attempt < attempts; ++attempt) {
    transport_->drain_input();  // a late reply to an earlier command must not answer this one
    outcome = transact(bytes, timeout, false, frame);
    if (outcome != Outcome::Corrupt) break;
  }
  switch (outcome) {
    case Outcome::Timeout:
      if (count_timeout) ++counters_.timeouts;
      r.status = CmdResult::Timeout;
      return r;
    case Outcome::Corrupt: r.status = CmdResult::Corrupt; return r;
    case Outcome::Reply: break;
  }
  AsciiReply a;
  if (parse_ascii_reply(frame.text(), a) != ParseError::None) {
    r.status = CmdResult::Corrupt;
    return r;
  }
  r.body = std::string(a.body);
  switch (a.kind) {
    case AsciiKind::Error:
      if (count_timeout) ++counters_.error_replies;  // not while probing: errors are expected there
      r.status = CmdResult::Error;
      r.error_code = a.error_code;
      break;
    case AsciiKind::Reset:
      ++counters_.resets;
      r.status = CmdResult::Reset;
      break;
    default: r.status = CmdResult::Ok; break;
  }
  return r;
}

bool Session::expect_ok(std::string_view name, std::string_view params, std::chrono::milliseconds timeout, CmdResult* out) {
  CmdResult r = command(name, params, timeout);
  if (out) *out = r;
  if (r.status == CmdResult::Ok) return true;
  std::string what = std::string(name) + ":" + std::string(params).substr(0, 12) + " on " + port_name_ + ": ";
  switch (r.status) {
    case CmdResult::Error: what += error_text(r.error_code); break;
    case CmdResult::Timeout: what += "no reply within " + std::to_string(timeout.count()) + " ms"; break;
    case CmdResult::Corrupt: what += "corrupt reply (CRC)"; break;
    case CmdResult::Reset: what += "device reset"; break;
    default: break;
  }
  fail_bring_up(what);
  return false;
}

// ---- bring-up -------------------------------------------------------------------------

void Session::open_port() {
  transport_ = open_port_();
  port_name_ = transport_->name();
  if (ever_opened_) ++counters_.reconnects;
  ever_opened_ = true;
  baud_ = 9600;
  reader_.clear();
  emit(Severity::Info, "NDI_PORT_OPENED", "opened " + port_name_);
}

void Session::close_port() { transport_.reset(); }

void Session::fail_bring_up(const std::string& why) { detail_ = why; }

bool Session::start() {
  if (state_ == LinkState::Tracking) return true;
  const bool recovering = state_ == LinkState::Recovering;
  if (!recovering) state_ = LinkState::Connecting;
  try {
    if (!transport_) {
      try {
        open_port();
      } catch (const PortError& e) {
        emit(Severity::Error, "NDI_PORT_OPEN_FAILED", e.what());
        if (!recovering) state_ = LinkState::Down;
        return false;
      }
    }
    if (!bring_up()) {
      emit(Severity::Error, "NDI_BRINGUP_FAILED", detail_);
      if (!recovering) state_ = LinkState::Down;
      return false;
    }
  } catch (const PortLost& e) {
    close_port();
    emit(Severity::Error, "NDI_PORT_LOST", e.what());
    if (!recovering) state_ = LinkState::Down;
    return false;
  } catch (const PortError& e) {
    emit(Severity::Error, "NDI_BRINGUP_FAILED", e.what());
    close_port();
    if (!recovering) state_ = LinkState::Down;
    return false;
  }
  state_ = LinkState::Tracking;
  consecutive_bad_ = consecutive_timeouts_ = 0;
  // On a network link the unit keeps tracking while the connection is down: frames it made
  // meanwhile are lost frames, counted from the gap when frames come again. (A device reset
  // restarts the counter: a lower number is not a gap. Serial links start afresh.)
  if (!transport_->is_network()) have_last_frame_ = false;
  std::string names;
  for (const auto& t : tools_) names += (names.empty() ? "" : ", ") + t.config.name + "=" + hex2(t.handle);
  emit(Severity::Info, "NDI_TRACKING_STARTED",
       "tracking on " + port_name_ + (transport_->is_network() ? std::string() : " at " + std::to_string(baud_) + " baud") +
           " with " + std::string(to_string(reply_mode())) +
           "; tools " + names);
  if (recovering) {
    emit(Severity::Info, "NDI_RECOVERED",
         "recovered after " + std::to_string((monotonic_us() - recovery_started_us_) / 1000) + " ms");
  }
  detail_.clear();
  return true;
}

bool Session::bring_up() {
  streaming_ = stream_wanted_ = use_bx2_ = false;
  api_major_ = 0;
  if (!establish_contact()) return false;
  if (state_ != LinkState::Recovering) state_ = LinkState::Initialising;
  if (!negotiate_baud()) return false;
  if (firmware_.empty() && !read_version()) return false;
  if (transport_->is_network()) choose_network_mode();
  free_stale_handles();
  for (auto& tool : tools_)
    if (!load_tool(tool)) return false;
  for (auto& tool : tools_)
    if (!expect_ok("PINIT", hex2(tool.handle), config_.setup_timeout)) return false;
  for (auto& tool : tools_) {
    CmdResult info;
    if (!expect_ok("PHINF", hex2(tool.handle) + "0001", config_.setup_timeout, &info)) return false;
    if (parse_phinf_basic(info.body, tool.info) != ParseError::None)
      emit(Severity::Warning, "NDI_BAD_REPLY", "PHINF reply for tool " + tool.config.name + " did not parse");
    if (!expect_ok("PENA", hex2(tool.handle) + "D", config_.setup_timeout)) return false;
    emit(Severity::Info, "NDI_TOOL_LOADED",
         "tool " + tool.config.name + " (" + tool.config.rom_path.string() + ") on handle " + hex2(tool.handle) +
             ", manufacturer " + tool.info.manufacturer + ", serial " + tool.info.serial_number);
  }
  previous_handles_.clear();
  for (const auto& t : tools_) previous_handles_.push_back(t.handle);
  if (!expect_ok("TSTART", "", config_.setup_timeout)) return false;
  return !stream_wanted_ || start_stream();
}

// ---- network links (TCP) --------------------------------------------------------------

bool Session::contact_network() {
  // No break and no baud rate on TCP. The device may still be tracking (and streaming) for
  // a connection that was lost: stop both before INIT. Errors are expected here.
  firmware_.clear();
  transport_->drain_input();
  reader_.clear();
  command("USTREAM", "--id=" + config_.stream_id, config_.setup_timeout, false);
  command("TSTOP", "", config_.setup_timeout, false);
  return init_device();
}

bool Session::choose_network_mode() {
  // APIREV: "G.003.005" (interface letter, major, minor). BX2 and STREAM need major >= 3.
  CmdResult r = command("APIREV", "", config_.setup_timeout, false);
  api_major_ = 0;
  if (r.status == CmdResult::Ok) {
    const auto dot = r.body.find('.');
    if (dot != std::string::npos) {
      int revision = 0;
      std::size_t i = dot + 1;
      for (; i < r.body.size() && i < dot + 4 && r.body[i] >= '0' && r.body[i] <= '9'; ++i) revision = revision * 10 + (r.body[i] - '0');
      if (i > dot + 1) api_major_ = revision;
    }
  }
  use_bx2_ = use_bx_ && api_major_ >= 3;
  stream_wanted_ = use_bx2_ && config_.stream;
  emit(Severity::Info, "NDI_API_REVISION",
       port_name_ + ": API revision '" + (r.status == CmdResult::Ok ? r.body : std::string("unknown")) + "': " +
           (stream_wanted_ ? "streaming BX2" : use_bx2_ ? "polling BX2" : use_bx_ ? "polling BX" : "polling TX"));
  return true;
}

bool Session::start_stream() {
  CmdResult r = command("STREAM", "--id=" + config_.stream_id + " BX2 --6d=tools", config_.setup_timeout);
  if (r.status == CmdResult::Ok) {
    streaming_ = true;
    return true;
  }
  if (r.status == CmdResult::Error) {
    emit(Severity::Warning, "NDI_STREAM_REFUSED",
         "STREAM refused on " + port_name_ + " (" + error_text(r.error_code) + "): polling BX2 instead");
    return true;
  }
  fail_bring_up("STREAM on " + port_name_ + ": " + (r.status == CmdResult::Timeout ? "no reply" : "corrupt reply"));
  return false;
}

Session::Outcome Session::read_stream_frame(Frame& frame) {
  const auto deadline = std::chrono::steady_clock::now() + config_.tracking_timeout;
  reader_.set_expect_binary(true);
  for (;;) {
    while (reader_.next(frame)) {
      // Poses only from our stream's packets; a binary reply outside a packet (its packet
      // header was damaged) or another stream's packet is set aside. ASCII replies outside
      // packets (RESET, ERROR) go to the caller.
      const bool ours = frame.streamed() && frame.stream() == config_.stream_id;
      if (!ours && (frame.streamed() || frame.kind != Frame::Kind::Ascii)) {
        ++counters_.stray_stream_packets;
        continue;
      }
      return frame.crc_ok ? Outcome::Reply : Outcome::Corrupt;
    }
    if (cancel_ && *cancel_) return Outcome::Timeout;
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) return Outcome::Timeout;
    const std::size_t n = transport_->read(read_buf_, left);
    if (n > 0) {
      last_read_mono_us_ = monotonic_us();
      reader_.feed(std::span(read_buf_.data(), n));
    }
  }
}

bool Session::wait_for_reset() {
  Frame frame;
  const auto deadline = std::chrono::steady_clock::now() + config_.reset_wait;
  while (std::chrono::steady_clock::now() < deadline && !(cancel_ && *cancel_)) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (transact({}, left, false, frame) != Outcome::Reply) continue;
    AsciiReply a;
    if (parse_ascii_reply(frame.text(), a) == ParseError::None && a.kind == AsciiKind::Reset) {
      ++counters_.resets;
      return true;
    }
  }
  return false;
}

bool Session::probe_init(int baud) {
  if (!transport_->supports_baud(baud)) return false;
  set_baud(baud);
  transport_->drain_input();
  reader_.clear();
  CmdResult r = command("INIT", "", config_.probe_timeout, false);
  if (r.status != CmdResult::Ok && r.status != CmdResult::Error) return false;
  // Something answered at this rate. The unit was not reset, so it may still be tracking
  // for a crashed host (then INIT answers ERROR0C, or OKAY on some firmware): stop
  // tracking and initialise again; this INIT must succeed.
  command("TSTOP", "", config_.setup_timeout, false);
  r = command("INIT", "", config_.setup_timeout, false);
  return r.status == CmdResult::Ok;
}

bool Session::establish_contact() {
  if (transport_->is_network()) return contact_network();
  firmware_.clear();
  set_baud(9600);
  transport_->drain_input();
  reader_.clear();
  transport_->send_break(config_.break_duration);
  if (wait_for_reset()) return init_device();
  emit(Severity::Warning, "NDI_NO_RESET_REPLY",
       "no RESET from " + port_name_ + " after a serial break; probing with INIT at each baud rate");
  // 9600 first (fresh unit), then the rate we were using, then the rest fastest first.
  std::vector<int> order = {9600, config_.target_baud};
  for (int b : kDeviceBauds) order.push_back(b);
  std::set<int> tried;
  for (int b : order) {
    if (cancel_ && *cancel_) break;
    if (!tried.insert(b).second) continue;
    if (probe_init(b)) {
      emit(Severity::Info, "NDI_CONTACT", "device answered INIT at " + std::to_string(b) + " baud on " + port_name_);
      return true;
    }
  }
  fail_bring_up("no reply from the device on " + port_name_ + " at any baud rate (is it powered and connected?)");
  return false;
}

bool Session::init_device() {
  // ERROR0C right after power-on means the unit is still booting: retry for a while.
  for (int attempt = 0; attempt < 10 && !(cancel_ && *cancel_); ++attempt) {
    CmdResult r = command("INIT", "", config_.setup_timeout);
    if (r.status == CmdResult::Ok) return true;
    if (!(r.status == CmdResult::Error && r.error_code == 0x0C)) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
  }
  return expect_ok("INIT", "", config_.setup_timeout);
}

bool Session::negotiate_baud() {
  if (transport_->is_network()) return read_version();  // no COMM on TCP
  std::vector<int> candidates;
  for (int b : kDeviceBauds)
    if (b <= config_.target_baud && transport_->supports_baud(b) && !failed_bauds_.count(b)) candidates.push_back(b);
  for (int rate : candidates) {
    if (rate == baud_) return read_version();
    CmdResult r = command("COMM", *comm_params(rate), config_.setup_timeout);
    if (r.status == CmdResult::Ok) {
      std::this_thread::sleep_for(config_.comm_settle);
      set_baud(rate);
      transport_->drain_input();
      if (read_version()) return true;
      // Switched but the link does not work at this rate: back to a known state.
      failed_bauds_.insert(rate);
      emit(Severity::Warning, "NDI_BAUD_FALLBACK",
           "no valid reply at " + std::to_string(rate) + " baud on " + port_name_ + "; trying a lower rate");
      if (!establish_contact()) return false;
      continue;
    }
    failed_bauds_.insert(rate);
    emit(Severity::Warning, "NDI_BAUD_FALLBACK",
         "COMM to " + std::to_string(rate) + " baud refused on " + port_name_ + " (" +
             (r.status == CmdResult::Error ? error_text(r.error_code) : std::string("no valid reply")) +
             "); trying a lower rate");
    // No valid reply: the device may or may not have switched; find it again.
    if (r.status != CmdResult::Error && !establish_contact()) return false;
  }
  if (baud_ == 9600 || candidates.empty()) return read_version();
  fail_bring_up("no working baud rate on " + port_name_);
  return false;
}

bool Session::read_version() {
  CmdResult r;
  if (!expect_ok("VER", "0", config_.setup_timeout, &r)) return false;
  VersionInfo v;
  if (parse_ver(r.body, v) != ParseError::None) {
    fail_bring_up("VER:0 reply did not parse on " + port_name_);
    return false;
  }
  firmware_ = v.firmware;
  serial_ = v.serial_number;
  version_lines_ = v.lines;
  use_bx_ = config_.use_bx && !bx_unreliable_;  // a BX fallback lasts for the process lifetime
  for (const auto& pattern : config_.tx_firmware) {
    if (r.body.find(pattern) != std::string::npos && use_bx_) {
      use_bx_ = false;
      emit(Severity::Warning, "NDI_TX_FALLBACK", "firmware matches '" + pattern + "' (BX unreliable): polling with TX");
    }
  }
  emit(Severity::Info, "NDI_LINK_UP",
       port_name_ + " at " + std::to_string(baud_) + " baud; firmware '" + firmware_ + "', S/N " + serial_);
  return true;
}

void Session::free_stale_handles() {
  std::vector<std::uint8_t> to_free = previous_handles_;
  CmdResult r = command("PHSR", "01", config_.setup_timeout);
  std::vector<PhsrEntry> entries;
  if (r.status == CmdResult::Ok && parse_phsr(r.body, entries) == ParseError::None)
    for (const auto& e : entries) to_free.push_back(e.handle);
  std::sort(to_free.begin(), to_free.end());
  to_free.erase(std::unique(to_free.begin(), to_free.end()), to_free.end());
  // Errors are expected (a reset already freed them) and are not counted.
  for (std::uint8_t h : to_free) command("PHF", hex2(h), config_.setup_timeout, false);
  previous_handles_.clear();
}

bool Session::load_tool(LoadedTool& tool) {
  CmdResult r;
  if (!expect_ok("PHRQ", "*********1****", config_.setup_timeout, &r)) return false;
  if (parse_phrq(r.body, tool.handle) != ParseError::None) {
    fail_bring_up("PHRQ reply '" + r.body + "' is not a port handle");
    return false;
  }
  previous_handles_.push_back(tool.handle);
  const auto& bytes = tool.rom.bytes;
  for (std::size_t chunk = 0; chunk < tool.rom.chunk_count(); ++chunk) {
    const std::size_t offset = chunk * 64;
    std::span<const std::uint8_t> data;
    if (offset < bytes.size()) data = std::span(bytes).subspan(offset, std::min<std::size_t>(64, bytes.size() - offset));
    const std::string params = pvwr_params(tool.handle, static_cast<std::uint16_t>(offset), data);
    bool ok = false;
    for (int attempt = 0; attempt <= config_.pvwr_retries && !ok; ++attempt) {
      r = command("PVWR", params, config_.setup_timeout);
      ok = r.status == CmdResult::Ok;
      if (r.status == CmdResult::Reset) break;
    }
    if (!ok) {
      fail_bring_up("loading " + tool.config.rom_path.string() + " for tool " + tool.config.name + ": PVWR at " +
                    std::to_string(offset) + " failed (" +
                    (r.status == CmdResult::Error ? error_text(r.error_code) : std::string("no valid reply")) + ")");
      return false;
    }
  }
  return true;
}

// ---- tracking ---------------------------------------------------------------------------

void Session::begin_recovery(std::string_view code, const std::string& why) {
  emit(Severity::Warning, code, why);
  if (state_ != LinkState::Recovering) recovery_started_us_ = monotonic_us();
  state_ = LinkState::Recovering;
  emit(Severity::Warning, "NDI_RECOVERING", "re-initialising " + port_name_ + " after: " + why);
}

bool Session::last_chance_poll(std::string_view mode, Frame& frame, Outcome& outcome) {
  // Replies missing timeouts_before_recovery times in a row: before the re-initialisation
  // (a break, up to reset_wait for RESET, baud probing, ROMs again: ~4 s without poses) the
  // command is sent once more and given setup_timeout to answer. A link that only stalled (a
  // pty on a loaded machine; a USB-serial adapter's latency spike) answers and tracking goes
  // on (NDI_RESYNCED); a device that is gone or reset does not, and recovery starts.
  const std::string why = std::to_string(consecutive_timeouts_) + " consecutive " + std::string(mode) + " replies missing on " + port_name_;
  if (!streaming_) {
    try {
      outcome = transact(use_bx2_ ? bx2_command_ : use_bx_ ? bx_command_ : tx_command_, config_.setup_timeout, use_bx_ || use_bx2_, frame);
    } catch (const PortLost& e) {
      close_port();
      begin_recovery("NDI_PORT_LOST", e.what());
      return false;
    }
    if (outcome != Outcome::Timeout) {
      emit(Severity::Warning, "NDI_RESYNCED", why + "; the device answered within " + std::to_string(config_.setup_timeout.count()) + " ms: tracking goes on");
      consecutive_timeouts_ = 0;
      return true;
    }
    ++counters_.timeouts;
  }
  begin_recovery("NDI_TIMEOUT", why);
  return false;
}

PollResult Session::poll(TrackingReply& out, std::int64_t& receive_mono_us) {
  out.count = 0;
  if (state_ != LinkState::Tracking || !transport_) return PollResult::Failed;
  const std::string_view mode = to_string(reply_mode());  // no allocation per frame
  Frame frame;
  Outcome outcome;
  try {
    if (streaming_) outcome = read_stream_frame(frame);
    else
      outcome = transact(use_bx2_ ? bx2_command_ : use_bx_ ? bx_command_ : tx_command_, config_.tracking_timeout,
                         use_bx_ || use_bx2_, frame);
  } catch (const PortLost& e) {
    close_port();
    streaming_ = false;
    begin_recovery("NDI_PORT_LOST", e.what());
    return PollResult::Failed;
  }
  ParseError parse = ParseError::None;
  if (outcome == Outcome::Timeout) {
    ++counters_.timeouts;
    ++consecutive_timeouts_;
    if (consecutive_timeouts_ < config_.timeouts_before_recovery) {
      emit(Severity::Warning, "NDI_TIMEOUT", std::string(mode) + " reply missing on " + port_name_);
      return PollResult::Failed;
    }
    if (!last_chance_poll(mode, frame, outcome)) return PollResult::Failed;
  }
  consecutive_timeouts_ = 0;
  if (outcome == Outcome::Reply) {
    receive_mono_us = last_read_mono_us_;
    if (frame.kind == Frame::Kind::Binary) {
      // The reader checked both CRCs.
      parse = use_bx2_ ? parse_bx2(frame.bytes, out, true) : parse_bx(frame.bytes, out, BxCrc::AlreadyChecked);
      if (parse != ParseError::None) ++counters_.bad_replies;
    } else if (frame.kind == Frame::Kind::Extended) {
      parse = ParseError::WrongKind;  // no CRC: never a source of poses
      ++counters_.bad_replies;
    } else {
      AsciiReply a;
      parse = parse_ascii_reply(frame.text(), a);
      if (parse == ParseError::None && a.kind == AsciiKind::Reset) {
        ++counters_.resets;
        streaming_ = false;
        begin_recovery("NDI_DEVICE_RESET", "the device reset itself (RESET received while tracking on " + port_name_ + ")");
        return PollResult::Failed;
      }
      if (parse == ParseError::None && a.kind == AsciiKind::Error) {
        ++counters_.error_replies;
        emit(Severity::Warning, "NDI_ERROR_REPLY", std::string(mode) + ": " + error_text(a.error_code));
        parse = ParseError::WrongKind;
      } else if (parse == ParseError::None) {
        parse = (use_bx_ || use_bx2_) ? ParseError::WrongKind : parse_tx(a.body, out);
      }
      if (parse != ParseError::None && a.kind != AsciiKind::Error) ++counters_.bad_replies;
    }
  }
  if (outcome == Outcome::Corrupt || parse != ParseError::None) {
    out.count = 0;  // never a pose from a corrupt or unparsable reply
    out.has_frame = out.has_device_time = false;
    ++consecutive_bad_;
    if (outcome == Outcome::Corrupt)
      emit(Severity::Warning, "NDI_CRC_ERROR", std::string(mode) + " reply failed its CRC on " + port_name_);
    else if (parse != ParseError::WrongKind)
      emit(Severity::Warning, "NDI_BAD_REPLY", std::string(mode) + " reply did not parse: " + std::string(to_string(parse)));
    if (use_bx_ && !use_bx2_ && consecutive_bad_ >= config_.bx_failures_before_tx) {
      use_bx_ = false;
      bx_unreliable_ = true;
      consecutive_bad_ = 0;
      emit(Severity::Warning, "NDI_TX_FALLBACK",
           std::to_string(config_.bx_failures_before_tx) + " consecutive bad BX replies on " + port_name_ +
               ": polling with TX from now on");
    } else if (consecutive_bad_ >= config_.bad_replies_before_recovery) {
      streaming_ = false;
      begin_recovery("NDI_LINK_UNRELIABLE", std::to_string(consecutive_bad_) + " consecutive bad replies on " + port_name_);
    }
    return PollResult::Failed;
  }
  consecutive_bad_ = 0;
  return finish_frame(out);
}

// Frame bookkeeping: system status changes, repeated frames, and frames lost, counted
// from gaps in the device's frame numbers (not from host timing).
PollResult Session::finish_frame(TrackingReply& out) {
  const std::uint32_t fn = out.frame_number();
  if (out.system_status != last_system_status_) {
    if (out.system_status != 0) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "%04X", out.system_status);
      emit(Severity::Warning, "NDI_SYSTEM_STATUS", std::string("system status 0x") + buf + " on " + port_name_);
    }
    last_system_status_ = out.system_status;
  }
  if (have_last_frame_ && fn == last_frame_) return PollResult::SameFrame;
  if (have_last_frame_ && fn > last_frame_ + 1) {
    counters_.dropped_frames += fn - last_frame_ - 1;
  }
  have_last_frame_ = true;
  last_frame_ = fn;
  ++counters_.frames_total;
  return PollResult::NewFrame;
}

bool Session::probe(ProbeResult& out) {
  out = ProbeResult{};
  bool ok = false;
  try {
    if (!transport_) open_port();
    ok = establish_contact() && negotiate_baud() && (!firmware_.empty() || read_version());
    if (ok) {
      out.baud = baud_;
      out.firmware = firmware_;
      out.serial_number = serial_;
      out.version_lines = version_lines_;
      CmdResult r = command("PHSR", "00", config_.setup_timeout);
      std::vector<PhsrEntry> entries;
      if (r.status == CmdResult::Ok && parse_phsr(r.body, entries) == ParseError::None) {
        for (const auto& e : entries) {
          ProbeResult::Handle h;
          h.handle = e.handle;
          h.status = e.status;
          CmdResult info = command("PHINF", hex2(e.handle) + "0001", config_.setup_timeout);
          h.has_info = info.status == CmdResult::Ok && parse_phinf_basic(info.body, h.info) == ParseError::None;
          out.handles.push_back(h);
        }
      }
    }
  } catch (const std::exception& e) {
    detail_ = e.what();
    ok = false;
  }
  stop();
  return ok;
}

void Session::stop() {
  stopping_ = true;  // talk to the device even when cancelled
  if (!transport_) {
    state_ = LinkState::Down;
    return;
  }
  try {
    if (streaming_) {
      // Stream packets may still arrive before USTREAM's OKAY: transact() sets them aside.
      command("USTREAM", "--id=" + config_.stream_id, config_.setup_timeout);
      streaming_ = false;
    }
    command("TSTOP", "", config_.setup_timeout);
    if (baud_ != 9600) {
      CmdResult r = command("COMM", "00000", config_.setup_timeout);
      if (r.status == CmdResult::Ok) {
        std::this_thread::sleep_for(config_.comm_settle);
        set_baud(9600);
      }
    }
    emit(Severity::Info, "NDI_TRACKING_STOPPED",
         "tracking stopped on " + port_name_ + (transport_->is_network() ? std::string() : ", device back at 9600 baud"));
  } catch (const std::exception& e) {
    emit(Severity::Warning, "NDI_STOP_FAILED", std::string("could not stop cleanly: ") + e.what());
  }
  close_port();
  state_ = LinkState::Down;
  stopping_ = false;
}

}  // namespace arnav::ndi
