#include "hil_tests/polaris_sim/vega_server.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <iostream>
#include <stdexcept>

#include "appliance/ndi/bx2.hpp"
#include "appliance/ndi/command.hpp"
#include "appliance/ndi/crc16.hpp"
#include "appliance/ndi/frame_reader.hpp"
#include "hil_tests/polaris_sim/scenario.hpp"
#include "protocol/clock.hpp"

namespace arnav::hil {
namespace {

constexpr std::uint8_t kInvalidCommand = 0x01;
constexpr std::uint8_t kInvalidMode = 0x0C;
constexpr std::uint8_t kOutOfRange = 0x23;
constexpr std::size_t kMaxLine = 4096;
constexpr double kSplitGapS = 0.0005;  // between the halves of a split packet
constexpr std::size_t kMaxLatenessSamples = 4'000'000;  // ~2.8 h at 400 Hz

double mono_s() { return static_cast<double>(monotonic_us()) * 1e-6; }

// Value of "--name=value" in a STREAM/USTREAM parameter list ("" when absent).
std::string option_value(const std::string& params, const std::string& name) {
  const std::string key = "--" + name + "=";
  const auto at = params.find(key);
  if (at == std::string::npos) return {};
  const auto start = at + key.size();
  return params.substr(start, params.find(' ', start) - start);
}

Bytes stream_packet(const std::string& id, const Bytes& reply) {
  Bytes out;
  out.reserve(6 + id.size() + reply.size());
  for (std::uint8_t b : {ndi::kStreamStart0, ndi::kStreamStart1, static_cast<std::uint8_t>(id.size() & 0xFF),
                         static_cast<std::uint8_t>(id.size() >> 8)})
    out.push_back(b);
  for (char c : id) out.push_back(static_cast<std::uint8_t>(c));
  const std::uint16_t crc = ndi::crc16(std::span(out));
  out.push_back(static_cast<std::uint8_t>(crc & 0xFF));
  out.push_back(static_cast<std::uint8_t>(crc >> 8));
  out.insert(out.end(), reply.begin(), reply.end());
  return out;
}

void log(const std::string& what) { std::cerr << "arnav-vega-sim: " << what << std::endl; }

}  // namespace

VegaFault parse_vega_fault(const std::string& spec) {
  const auto colon = spec.find(':');
  if (colon == std::string::npos) throw ScenarioError("--fault '" + spec + "': expected AT_S:KIND, e.g. '5:reset'");
  VegaFault f;
  f.text = spec;
  try {
    f.at_s = std::stod(spec.substr(0, colon));
  } catch (const std::exception&) {
    throw ScenarioError("--fault '" + spec + "': AT_S must be a number of seconds");
  }
  std::string rest = spec.substr(colon + 1);
  const auto space = rest.find(' ');
  const std::string kind = rest.substr(0, space);
  const std::string arg = space == std::string::npos ? "" : rest.substr(space + 1);
  auto number = [&](double def, double lo, double hi) {
    if (arg.empty()) return def;
    double v = 0;
    try {
      std::size_t used = 0;
      v = std::stod(arg, &used);
      if (used != arg.size()) throw std::invalid_argument(arg);
    } catch (const std::exception&) {
      throw ScenarioError("--fault '" + spec + "': '" + arg + "' is not a number");
    }
    if (!(v >= lo && v <= hi)) throw ScenarioError("--fault '" + spec + "': " + arg + " is outside " + std::to_string(lo) + ".." + std::to_string(hi));
    return v;
  };
  if (!(f.at_s >= 0.0)) throw ScenarioError("--fault '" + spec + "': AT_S must be >= 0");
  if (kind == "reset") f.kind = VegaFault::Kind::kReset;
  else if (kind == "stall") f.kind = VegaFault::Kind::kStall, f.seconds = number(0.05, 0.0, 60.0);
  else if (kind == "bad_crc") f.kind = VegaFault::Kind::kBadCrc, f.count = static_cast<int>(number(1, 1, 1e6));
  else if (kind == "split") f.kind = VegaFault::Kind::kSplit, f.count = static_cast<int>(number(1, 1, 1e6));
  else if (kind == "skip") f.kind = VegaFault::Kind::kSkip, f.count = static_cast<int>(number(1, 1, 1e6));
  else if (kind == "duplicate") f.kind = VegaFault::Kind::kDuplicate, f.count = static_cast<int>(number(1, 1, 1e6));
  else throw ScenarioError("--fault '" + spec + "': unknown kind '" + kind + "' (reset, stall S, bad_crc N, split N, skip N, duplicate N)");
  if (f.kind == VegaFault::Kind::kReset && !arg.empty()) throw ScenarioError("--fault '" + spec + "': reset takes no argument");
  return f;
}

VegaServer::VegaServer(PolarisModel& model, VegaOptions options, std::vector<VegaFault> faults)
    : model_(model), options_(std::move(options)), faults_(std::move(faults)), fault_done_(faults_.size(), false) {
  model_.set_api_revision(options_.api_revision);
}

VegaServer::~VegaServer() {
  if (client_fd_ >= 0) ::close(client_fd_);
  if (listen_fd_ >= 0) ::close(listen_fd_);
}

double VegaServer::now_s() const { return mono_s() - t0_mono_s_; }

int VegaServer::start() {
  const std::string where = options_.bind_address + ":" + std::to_string(options_.port);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<std::uint16_t>(options_.port));
  if (::inet_pton(AF_INET, options_.bind_address.c_str(), &addr.sin_addr) != 1)
    throw std::runtime_error(where + ": not an IPv4 address to bind");
  listen_fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (listen_fd_ < 0) throw std::runtime_error(where + ": socket: " + std::strerror(errno));
  const int one = 1;
  ::setsockopt(listen_fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  if (::bind(listen_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 || ::listen(listen_fd_, 4) != 0)
    throw std::runtime_error(where + ": cannot listen: " + std::strerror(errno));
  socklen_t len = sizeof addr;
  ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len);
  t0_mono_s_ = mono_s();
  model_.set_clock_origin_mono_s(t0_mono_s_);
  return ntohs(addr.sin_port);
}

void VegaServer::accept_client() {
  const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
  if (fd < 0) return;
  if (client_fd_ >= 0) close_client(false);  // a new host connection replaces the old one
  client_fd_ = fd;
  const int one = 1;
  ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  ++stats_.connections;
  log("host connected (connection " + std::to_string(stats_.connections) + ")");
}

void VegaServer::close_client(bool reset) {
  if (client_fd_ < 0) return;
  if (reset) {
    const linger l{1, 0};  // close with RST, as a device that drops the link
    ::setsockopt(client_fd_, SOL_SOCKET, SO_LINGER, &l, sizeof l);
  }
  ::close(client_fd_);
  client_fd_ = -1;
  input_.clear();
  output_.clear();
  streaming_ = false;  // the stream belonged to the connection; tracking goes on
  stall_until_s_ = -1.0;
}

void VegaServer::queue(Bytes bytes, double now, double frame_time_s) {
  const double due = std::max(now, output_.empty() ? now : output_.back().due_s);
  if (split_left_ > 0 && bytes.size() > 2) {
    --split_left_;
    const auto half = static_cast<std::ptrdiff_t>(bytes.size() / 2);
    output_.push_back({due, Bytes(bytes.begin(), bytes.begin() + half)});
    output_.push_back({due + kSplitGapS, Bytes(bytes.begin() + half, bytes.end()), frame_time_s});
    return;
  }
  output_.push_back({due, std::move(bytes), frame_time_s});
}

void VegaServer::flush(double now) {
  while (client_fd_ >= 0 && !output_.empty() && output_.front().due_s <= now && now >= stall_until_s_) {
    Pending& p = output_.front();
    const ssize_t n = ::send(client_fd_, p.bytes.data(), p.bytes.size(), MSG_NOSIGNAL);
    if (n < 0) {
      if (errno == EAGAIN || errno == EINTR) return;  // the host reads slowly: keep the rest
      log(std::string("send failed: ") + std::strerror(errno) + "; dropping the connection");
      close_client(false);
      return;
    }
    if (static_cast<std::size_t>(n) < p.bytes.size()) {
      p.bytes.erase(p.bytes.begin(), p.bytes.begin() + n);
      return;
    }
    if (p.frame_time_s >= 0.0 && send_lateness_us_.size() < kMaxLatenessSamples)
      send_lateness_us_.push_back(static_cast<float>((now_s() - p.frame_time_s) * 1e6));
    output_.pop_front();
  }
}

void VegaServer::on_client_bytes(double now) {
  std::uint8_t buf[4096];
  const ssize_t n = ::recv(client_fd_, buf, sizeof buf, 0);
  if (n == 0 || (n < 0 && errno != EAGAIN && errno != EINTR)) {
    log("host closed the connection");
    close_client(false);
    return;
  }
  for (ssize_t i = 0; i < n; ++i) {
    if (buf[i] == '\r') {
      std::string line;
      line.swap(input_);
      if (!line.empty()) handle_line(line, now);
      if (client_fd_ < 0) return;
    } else if (input_.size() < kMaxLine) {
      input_.push_back(static_cast<char>(buf[i]));
    }
  }
}

void VegaServer::handle_line(const std::string& line, double now) {
  ++stats_.commands;
  const auto decoded = ndi::decode_command(line);
  if (decoded && !(decoded->has_crc && !decoded->crc_ok)) {
    if (decoded->name == "STREAM") return handle_stream(std::string(decoded->params), now);
    if (decoded->name == "USTREAM") return handle_ustream(std::string(decoded->params), now);
  }
  Bytes in(line.begin(), line.end());
  in.push_back('\r');
  for (auto& r : model_.receive(in, now)) queue(std::move(r.bytes), now);
  if (streaming_ && !model_.tracking()) streaming_ = false;  // TSTOP ends the stream's data
  if (!timeline_start_s_ && model_.first_tstart_s()) timeline_start_s_ = now;
}

void VegaServer::handle_stream(const std::string& params, double now) {
  const std::string id = option_value(params, "id");
  if (!options_.stream_supported) return queue(error_reply(kInvalidCommand), now);
  if (id.empty() || id.size() > ndi::kMaxStreamId || params.find("BX2") == std::string::npos ||
      params.find("--6d=tools") == std::string::npos)
    return queue(error_reply(kOutOfRange), now);
  if (!model_.tracking()) return queue(error_reply(kInvalidMode), now);
  queue(okay_reply(), now);
  streaming_ = true;
  stream_id_ = id;
  next_frame_ = model_.frame_at(now) + 1;
  timeline_start_s_ = now;
  log("streaming BX2 as '" + id + "' from frame " + std::to_string(next_frame_));
}

void VegaServer::handle_ustream(const std::string& params, double now) {
  if (!streaming_ || option_value(params, "id") != stream_id_) return queue(error_reply(kOutOfRange), now);
  // Packets already on their way reach the host before the OKAY.
  for (int i = 0; i < options_.ustream_race_packets; ++i) emit_frame(next_frame_++, now);
  streaming_ = false;
  queue(okay_reply(), now);
}

void VegaServer::emit_frame(std::uint32_t frame, double now) {
  Bytes reply;
  ndi::encode_bx2(model_.bx2_frame(frame, now), reply);
  if (bad_crc_left_ > 0) {
    --bad_crc_left_;
    reply.back() ^= 0x5A;  // the body CRC no longer matches
  }
  const int copies = duplicate_left_ > 0 ? 2 : 1;
  if (duplicate_left_ > 0) --duplicate_left_;
  const double frame_time_s = model_.frame_time_mono_s(frame) - t0_mono_s_;
  for (int i = 0; i < copies; ++i) {
    queue(stream_packet(stream_id_, reply), now, frame_time_s);
    ++stats_.stream_packets;
  }
}

void VegaServer::send_due_frames(double now) {
  if (!streaming_ || client_fd_ < 0 || now < stall_until_s_) return;
  const std::uint32_t due = model_.frame_at(now);
  while (streaming_ && next_frame_ <= due) emit_frame(next_frame_++, now);
}

void VegaServer::run_timeline(double now) {
  if (!timeline_start_s_) return;
  for (std::size_t i = 0; i < faults_.size(); ++i) {
    if (fault_done_[i] || now - *timeline_start_s_ < faults_[i].at_s) continue;
    fault_done_[i] = true;
    const VegaFault& f = faults_[i];
    ++stats_.faults;
    log("fault: " + f.text);
    switch (f.kind) {
      case VegaFault::Kind::kReset:
        ++stats_.resets;
        close_client(true);
        break;
      case VegaFault::Kind::kStall: stall_until_s_ = now + f.seconds; break;
      case VegaFault::Kind::kBadCrc: bad_crc_left_ += f.count; break;
      case VegaFault::Kind::kSplit: split_left_ += f.count; break;
      case VegaFault::Kind::kSkip:
        next_frame_ += static_cast<std::uint32_t>(f.count);  // these frame numbers are never sent
        stats_.frames_skipped += static_cast<std::uint64_t>(f.count);
        break;
      case VegaFault::Kind::kDuplicate: duplicate_left_ += f.count; break;
    }
  }
}

double VegaServer::next_wakeup_s(double now) const {
  double wake = now + 0.05;
  if (streaming_ && client_fd_ >= 0)
    wake = std::min(wake, model_.frame_time_mono_s(next_frame_) - t0_mono_s_);
  if (!output_.empty()) wake = std::min(wake, output_.front().due_s);
  if (stall_until_s_ > now) wake = std::max(wake, stall_until_s_);
  return wake;
}

void VegaServer::run(const std::atomic<bool>& stop) {
  while (!stop.load()) {
    double now = now_s();
    const double wait_s = std::max(0.0, next_wakeup_s(now) - now);
    pollfd fds[2] = {{listen_fd_, POLLIN, 0}, {client_fd_, static_cast<short>(POLLIN | (output_.empty() ? 0 : POLLOUT)), 0}};
    timespec ts{static_cast<time_t>(wait_s), static_cast<long>((wait_s - std::floor(wait_s)) * 1e9)};
    const int rc = ::ppoll(fds, client_fd_ >= 0 ? 2 : 1, &ts, nullptr);
    if (rc < 0 && errno != EINTR) throw std::runtime_error(std::string("ppoll: ") + std::strerror(errno));
    now = now_s();
    if (rc > 0 && (fds[0].revents & POLLIN)) accept_client();
    if (rc > 0 && client_fd_ >= 0 && fds[1].fd == client_fd_ && (fds[1].revents & (POLLIN | POLLHUP | POLLERR))) on_client_bytes(now);
    run_timeline(now);
    send_due_frames(now);
    flush(now);
  }
  close_client(false);
}

}  // namespace arnav::hil
