#include "hil_tests/polaris_sim/simulator.hpp"

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "appliance/ndi/transcript.hpp"
#include "protocol/clock.hpp"

namespace arnav::hil {
namespace {

int bind_datagram_socket(const std::string& path) {
  sockaddr_un addr{};
  if (path.size() >= sizeof addr.sun_path) throw std::runtime_error("socket path too long: " + path);
  const int fd = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd < 0) throw std::runtime_error("socket: " + std::string(std::strerror(errno)));
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, path.c_str(), sizeof addr.sun_path - 1);
  ::unlink(path.c_str());
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0)
    throw std::runtime_error("bind " + path + ": " + std::strerror(errno));
  return fd;
}

// What a UART set to another rate makes of our bytes: noise, never a CR, so it cannot
// complete a reply by accident.
std::uint8_t noise_byte(std::uint8_t b) { return (b & 0x01) ? 0xFF : 0x80; }

constexpr double kMaxPollWaitS = 0.02;
constexpr std::size_t kMaxQueuedBytes = 1 << 20;

}  // namespace

Simulator::Simulator(SimDevice& device, std::vector<TimedFault> timeline, SimulatorOptions options)
    : device_(device),
      timeline_(std::move(timeline)),
      timeline_done_(timeline_.size(), false),
      options_(std::move(options)),
      link_(options_.pty_link, options_.bind_over),
      rng_(options_.seed) {
  t0_mono_s_ = static_cast<double>(monotonic_us()) * 1e-6;
  device_.set_clock_origin_mono_s(t0_mono_s_);
}

Simulator::~Simulator() {
  if (break_fd_ >= 0) {
    ::close(break_fd_);
    ::unlink(options_.break_socket.c_str());
  }
  if (control_fd_ >= 0) {
    ::close(control_fd_);
    ::unlink(options_.control_socket.c_str());
  }
}

double Simulator::now_s() const { return static_cast<double>(monotonic_us()) * 1e-6 - t0_mono_s_; }

void Simulator::event(const std::string& kind, const std::string& detail) {
  std::cerr << "arnav-polaris-sim: t=" << now_s() << " s " << kind << (detail.empty() ? "" : ": ") << detail << std::endl;
  if (events_.is_open()) {
    nlohmann::json j{{"mono_us", monotonic_us()}, {"t_s", now_s()}, {"event", kind}, {"detail", detail}};
    events_ << j.dump() << '\n';
    events_.flush();
  }
}

std::string Simulator::start() {
  if (!options_.truth_csv.empty()) {
    truth_.open(options_.truth_csv);
    if (!truth_) throw std::runtime_error("cannot write ground truth file " + options_.truth_csv);
    truth_ << "frame,handle,tool,valid,port_status,qw,qx,qy,qz,x_mm,y_mm,z_mm,"
              "reported_qw,reported_qx,reported_qy,reported_qz,reported_x_mm,reported_y_mm,reported_z_mm,rms_error_mm,dropout\n";
  }
  if (!options_.events_jsonl.empty()) {
    events_.open(options_.events_jsonl);
    if (!events_) throw std::runtime_error("cannot write events file " + options_.events_jsonl);
  }
  if (!options_.trace.empty()) {
    trace_.open(options_.trace);
    if (!trace_) throw std::runtime_error("cannot write trace file " + options_.trace);
    trace_ << ndi::kTranscriptHeader << "\n# arnav-polaris-sim session trace (device side)\n";
  }
  if (!options_.break_socket.empty()) break_fd_ = bind_datagram_socket(options_.break_socket);
  if (!options_.control_socket.empty()) control_fd_ = bind_datagram_socket(options_.control_socket);
  device_.reset(now_s());  // power-on: the unit boots silently at 9600
  link_.plug();
  event("port_ready", link_.slave_path());
  return link_.slave_path();
}

void Simulator::trace(int kind, const std::string& bytes, std::int64_t value) {
  if (!trace_.is_open()) return;
  ndi::TranscriptRecord r;
  r.t_us = static_cast<std::int64_t>(now_s() * 1e6);
  r.kind = static_cast<ndi::TranscriptRecord::Kind>(kind);
  r.bytes = bytes;
  r.value = value;
  trace_ << ndi::format_record(r) << '\n';
}

void Simulator::record_truth(const TruthRow& row) {
  if (!truth_.is_open()) return;
  if (row.frame_number != truth_last_frame_) {
    truth_seen_.clear();  // frames only move forward between resets
    truth_last_frame_ = row.frame_number;
  }
  if (!truth_seen_.insert({row.frame_number, row.handle}).second) return;
  const Eigen::Quaterniond q(row.X_NdiTool.rotation());
  const Eigen::Vector3d p = row.X_NdiTool.translation();
  // The reported pose (what the device sent; the true one when nothing was sent) beside the true one.
  const Eigen::Isometry3d& X_rep = row.valid ? row.X_NdiTool_reported : row.X_NdiTool;
  Eigen::Quaterniond qr(X_rep.rotation());
  if (qr.w() < 0) qr.coeffs() *= -1.0;
  const Eigen::Vector3d pr = X_rep.translation();
  char line[640];
  std::snprintf(line, sizeof line,
                "%u,%u,%s,%d,%u,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.6g,%d\n",
                row.frame_number, static_cast<unsigned>(row.handle), row.tool.empty() ? "-" : row.tool.c_str(), row.valid ? 1 : 0,
                row.port_status, q.w(), q.x(), q.y(), q.z(), p.x(), p.y(), p.z(), qr.w(), qr.x(), qr.y(), qr.z(), pr.x(), pr.y(),
                pr.z(), row.rms_error_mm, row.dropped_out ? 1 : 0);
  truth_ << line;
}

std::string Simulator::inject(const FaultCommand& f) {
  using K = FaultCommand::Kind;
  const double now = now_s();
  ++stats_.faults;
  switch (f.kind) {
    case K::kCablePull:
      link_.unplug();
      output_.clear();
      replug_due_s_ = now + f.duration_s;
      event("port_gone", f.text);
      return {};
    case K::kReset:
      output_.clear();
      send_reset(now);
      event("device_reset", f.text);
      return {};
    case K::kDropBytes: drop_next_ = f.count; break;
    case K::kGarble: garble_next_ = f.count; break;
    case K::kBadCrc: bad_crc_next_ = f.count; break;
    case K::kGarbage: garbage_next_ = f.count; break;
    case K::kPartial: partial_next_ = 1; break;
    case K::kChunked: chunked_until_s_ = now + f.duration_s; break;
    case K::kSlow:
      slow_next_ = f.count;
      slow_delay_s_ = f.delay_s;
      break;
    case K::kNoReply:
      if (!device_.swallow_commands(f.count)) return "this device (replay) cannot model lost commands";
      break;
    case K::kError:
      if (!device_.force_errors(f.code, f.count)) return "this device (replay) cannot model ERROR replies";
      break;
    case K::kMissing:
    case K::kOutOfVolume:
      if (!device_.hide_tool(f.tool, now + f.duration_s, f.kind == K::kOutOfVolume))
        return "no tool named '" + f.tool + "' in this scenario";
      break;
    case K::kBaudMismatch: {
      int baud = f.baud;
      if (baud == 0) baud = device_.baud() == 57600 ? 38400 : 57600;
      device_.set_baud(baud);
      break;
    }
  }
  event("fault", f.text);
  trace(static_cast<int>(ndi::TranscriptRecord::Kind::Note), "fault: " + f.text);
  return {};
}

void Simulator::send_reset(double now) {
  const Bytes msg = device_.reset(now);
  // The message goes out at 9600 whatever rate the host uses: noise if it is elsewhere.
  output_.push_back(Pending{now, msg, 0, true});
}

void Simulator::queue_reply(PolarisModel::Reply reply, double now) {
  Bytes b = std::move(reply.bytes);
  std::uniform_int_distribution<int> any_byte(0, 255);
  if (garbage_next_ > 0 && !b.empty()) {
    Bytes g(static_cast<std::size_t>(garbage_next_));
    for (auto& x : g) x = static_cast<std::uint8_t>(any_byte(rng_));
    b.insert(b.begin(), g.begin(), g.end());
    garbage_next_ = 0;
  }
  if (drop_next_ > 0 && !b.empty()) {
    for (int i = 0; i < drop_next_ && !b.empty(); ++i)
      b.erase(b.begin() + std::uniform_int_distribution<std::ptrdiff_t>(0, static_cast<std::ptrdiff_t>(b.size()) - 1)(rng_));
    drop_next_ = 0;
  }
  if (garble_next_ > 0 && !b.empty()) {
    for (int i = 0; i < garble_next_; ++i) {
      auto& x = b[std::uniform_int_distribution<std::size_t>(0, b.size() - 1)(rng_)];
      x = static_cast<std::uint8_t>(x ^ (1u << std::uniform_int_distribution<int>(0, 7)(rng_)));
    }
    garble_next_ = 0;
  }
  if (bad_crc_next_ > 0 && b.size() >= 4) {
    --bad_crc_next_;
    if (b[0] == 0xC4 && b.size() > 8) {
      b[b.size() - 1] ^= 0x5A;  // BX: body CRC
    } else {
      // Text: change the last CRC digit into another valid hex digit.
      std::uint8_t& d = b[b.size() - 2];
      d = d == '0' ? '1' : '0';
    }
  }
  if (partial_next_ > 0 && b.size() > 1) {
    b.resize(b.size() / 2);
    partial_next_ = 0;
  }
  double due = now;
  if (slow_next_ > 0) {
    --slow_next_;
    due += slow_delay_s_;
  }
  if (now < chunked_until_s_) {
    std::uniform_int_distribution<std::size_t> size(1, 7);
    std::uniform_real_distribution<double> gap(0.0002, 0.002);
    std::size_t at = 0;
    while (at < b.size()) {
      const std::size_t n = std::min(size(rng_), b.size() - at);
      const bool last = at + n == b.size();
      output_.push_back(Pending{due, Bytes(b.begin() + static_cast<std::ptrdiff_t>(at), b.begin() + static_cast<std::ptrdiff_t>(at + n)),
                                last ? reply.baud_after : 0, last});
      at += n;
      due += gap(rng_);
    }
    return;
  }
  output_.push_back(Pending{due, std::move(b), reply.baud_after, true});
}

void Simulator::on_host_bytes(double now) {
  std::uint8_t buf[4096];
  for (;;) {
    const ssize_t n = ::read(link_.master_fd(), buf, sizeof buf);
    if (n <= 0) return;  // EAGAIN, or EIO while no host has the port open
    stats_.bytes_in += static_cast<std::uint64_t>(n);
    // Bytes sent during a break or at another baud rate never form a command.
    if (in_break_ || reset_due_s_ >= 0.0 || link_.host_baud() != device_.baud()) {
      stats_.noise_bytes_in += static_cast<std::uint64_t>(n);
      continue;
    }
    if (trace_.is_open() && link_.host_baud() != traced_host_baud_) {
      traced_host_baud_ = link_.host_baud();
      trace(static_cast<int>(ndi::TranscriptRecord::Kind::Baud), {}, traced_host_baud_);
    }
    for (auto& r : device_.receive(std::span<const std::uint8_t>(buf, static_cast<std::size_t>(n)), now)) {
      ++stats_.commands;
      trace(static_cast<int>(ndi::TranscriptRecord::Kind::Command), r.command + "\r");
      queue_reply(std::move(r), now);
    }
  }
}

void Simulator::flush_output(double now) {
  while (!output_.empty() && link_.plugged()) {
    Pending& p = output_.front();
    if (p.due_s > now) return;
    if (options_.wire_timing && now < wire_free_s_) return;
    Bytes bytes = p.bytes;
    if (link_.host_baud() != device_.baud()) {
      for (auto& b : bytes) b = noise_byte(b);
      stats_.noise_bytes_out += bytes.size();
    }
    const ssize_t n = ::write(link_.master_fd(), bytes.data(), bytes.size());
    if (n < 0) return;  // pty buffer full: the host is not reading; try later
    trace(static_cast<int>(ndi::TranscriptRecord::Kind::Reply), std::string(bytes.begin(), bytes.begin() + n));
    stats_.bytes_out += static_cast<std::uint64_t>(n);
    if (options_.wire_timing) wire_free_s_ = std::max(wire_free_s_, now) + static_cast<double>(n) * 10.0 / device_.baud();
    if (static_cast<std::size_t>(n) < bytes.size()) {
      p.bytes.erase(p.bytes.begin(), p.bytes.begin() + n);
      return;
    }
    if (p.baud_after != 0) device_.set_baud(p.baud_after);  // COMM: switch after the OKAY
    if (p.last_piece) ++stats_.replies;
    output_.pop_front();
  }
}

void Simulator::handle_break_socket(double now) {
  char buf[128];
  for (;;) {
    const ssize_t n = ::recv(break_fd_, buf, sizeof buf - 1, 0);
    if (n <= 0) return;
    buf[n] = 0;
    const std::string msg(buf);
    if (!link_.plugged()) continue;
    ++stats_.breaks;
    // "on": break asserted; "off": released; "pulse": a timed break (tcsendbreak).
    if (msg.rfind("on", 0) == 0) {
      in_break_ = true;
      output_.clear();
      event("break", "asserted");
      trace(static_cast<int>(ndi::TranscriptRecord::Kind::Note), "break asserted");
    } else if (msg.rfind("off", 0) == 0 || msg.rfind("pulse", 0) == 0) {
      in_break_ = false;
      output_.clear();
      reset_due_s_ = now + options_.reset_delay_s;
      event("break", msg.rfind("off", 0) == 0 ? "released: device resets" : "pulse: device resets");
    }
  }
}

void Simulator::handle_control_socket() {
  char buf[512];
  for (;;) {
    sockaddr_un from{};
    socklen_t from_len = sizeof from;
    const ssize_t n = ::recvfrom(control_fd_, buf, sizeof buf - 1, 0, reinterpret_cast<sockaddr*>(&from), &from_len);
    if (n <= 0) return;
    buf[n] = 0;
    std::string text(buf);
    while (!text.empty() && (text.back() == '\n' || text.back() == '\r')) text.pop_back();
    std::string answer = "OK";
    try {
      const std::string why = inject(parse_fault(text, "control command"));
      if (!why.empty()) answer = "ERROR " + why;
    } catch (const ScenarioError& e) {
      answer = std::string("ERROR ") + e.what();
    }
    if (answer != "OK") event("control_rejected", answer);
    if (from_len > sizeof(sa_family_t))
      ::sendto(control_fd_, answer.data(), answer.size(), 0, reinterpret_cast<sockaddr*>(&from), from_len);
  }
}

void Simulator::run_timeline(double now) {
  const auto start = device_.first_tstart_s();
  if (!start) return;
  for (std::size_t i = 0; i < timeline_.size(); ++i) {
    if (timeline_done_[i] || now < *start + timeline_[i].at_s) continue;
    timeline_done_[i] = true;
    const std::string why = inject(timeline_[i].fault);
    if (!why.empty()) event("fault_not_applied", timeline_[i].fault.text + ": " + why);
  }
}

void Simulator::run(const std::atomic<bool>& stop) {
  while (!stop.load()) {
    double now = now_s();
    if (replug_due_s_ >= 0.0 && now >= replug_due_s_) {
      replug_due_s_ = -1.0;
      link_.plug();
      event("port_back", link_.slave_path());
    }
    if (reset_due_s_ >= 0.0 && now >= reset_due_s_) {
      reset_due_s_ = -1.0;
      send_reset(now);
      event("reset_sent", "RESET at 9600");
    }
    run_timeline(now);
    flush_output(now);
    std::size_t queued = 0;
    for (const auto& p : output_) queued += p.bytes.size();
    if (queued > kMaxQueuedBytes) {  // a host that stopped reading must not grow us forever
      event("output_dropped", "host is not reading: " + std::to_string(output_.size()) + " replies discarded");
      output_.clear();
    }
    if (truth_.is_open() && now - truth_flushed_s_ > 0.2) {
      truth_.flush();
      truth_flushed_s_ = now;
    }

    double wait = kMaxPollWaitS;
    if (!output_.empty()) wait = std::min(wait, std::max(0.0, std::max(output_.front().due_s, options_.wire_timing ? wire_free_s_ : 0.0) - now));
    if (reset_due_s_ >= 0.0) wait = std::min(wait, std::max(0.0, reset_due_s_ - now));
    // A reply that is due but could not be written (pty full: the host is not reading;
    // port unplugged) is retried every millisecond, not in a busy loop: the simulator may
    // run SCHED_FIFO, above the appliance.
    const bool output_blocked =
        !output_.empty() && output_.front().due_s <= now && !(options_.wire_timing && now < wire_free_s_);
    if (output_blocked) wait = std::max(wait, 0.001);
    pollfd fds[3];
    nfds_t nfds = 0;
    const int master = link_.plugged() ? link_.master_fd() : -1;
    fds[nfds++] = pollfd{master, POLLIN, 0};
    fds[nfds++] = pollfd{break_fd_, POLLIN, 0};
    fds[nfds++] = pollfd{control_fd_, POLLIN, 0};
    const int timeout_ms = static_cast<int>(std::ceil(wait * 1000.0));
    if (::poll(fds, nfds, timeout_ms) < 0 && errno != EINTR) throw std::runtime_error(std::string("poll: ") + std::strerror(errno));
    now = now_s();
    if (break_fd_ >= 0 && (fds[1].revents & POLLIN)) handle_break_socket(now);
    if (control_fd_ >= 0 && (fds[2].revents & POLLIN)) handle_control_socket();
    if (master >= 0 && link_.plugged() && (fds[0].revents & POLLIN)) on_host_bytes(now);
    flush_output(now);
  }
  if (truth_.is_open()) truth_.flush();
  if (trace_.is_open()) trace_.flush();
  link_.unplug();
}

}  // namespace arnav::hil
