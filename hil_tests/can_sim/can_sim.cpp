#include "hil_tests/can_sim/can_sim.hpp"

#include <fcntl.h>
#include <linux/can.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "appliance/can/candump_log.hpp"
#include "appliance/can/slcan.hpp"
#include "hil_tests/polaris_sim/pty_link.hpp"
#include "protocol/clock.hpp"

namespace arnav::hil {

struct CanSim::PtyState {
  PtyLink link;
  PtyState(std::string l, std::string b) : link(std::move(l), std::move(b)) {}
};

namespace {

std::runtime_error sys_error(const std::string& what) { return std::runtime_error(what + ": " + std::strerror(errno)); }

std::vector<std::string> words(const std::string& text) {
  std::istringstream in(text);
  std::vector<std::string> w;
  for (std::string s; in >> s;) w.push_back(s);
  return w;
}

bool to_number(const std::string& s, double& v) {
  try {
    std::size_t used = 0;
    v = std::stod(s, &used);
    return used == s.size();
  } catch (...) {
    return false;
  }
}

}  // namespace

std::string commands_help() {
  return "  press INPUT | release INPUT        change a switch (analogue: to the top / bottom of its range)\n"
         "  value INPUT V                      analogue input to raw value V\n"
         "  bounce INPUT N MS                  N contact bounces MS apart, ending in the opposite state\n"
         "  train INPUT N PERIOD_MS            N presses, each released half a period later\n"
         "  node DEVICE off|on                 the whole device goes silent / comes back\n"
         "  heartbeat DEVICE off|on            only its heartbeat / periodic frame stops / restarts\n"
         "  bus_off S                          controller bus-off for S seconds (no traffic), then restart\n"
         "  error_frames N                     N protocol error frames, error-passive for 0.5 s\n"
         "  garbage N                          slcan: N random bytes into the stream\n"
         "  drop_chars N                       slcan: one character lost from each of the next N lines\n"
         "  flood RATE S                       unrelated ids at RATE frames/s for S seconds\n"
         "  frame ID#DATA                      one raw frame (candump notation)\n";
}

std::vector<ScenarioStep> load_can_scenario(const std::string& path) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw std::runtime_error(path + ": cannot read the scenario file");
  } catch (const YAML::ParserException& e) {
    throw std::runtime_error(path + ":" + std::to_string(e.mark.line + 1) + ": YAML syntax error: " + e.msg);
  }
  auto fail = [&](const YAML::Node& n, const std::string& what) {
    throw std::runtime_error(path + ":" + std::to_string(n.Mark().line + 1) + ": " + what);
  };
  if (!root.IsMap()) throw std::runtime_error(path + ":1: expected a mapping with 'steps'");
  for (const auto& kv : root)
    if (kv.first.Scalar() != "steps") fail(kv.first, "unknown key '" + kv.first.Scalar() + "' (known: steps)");
  const YAML::Node steps = root["steps"];
  if (!steps || !steps.IsSequence()) fail(root, "'steps' must be a list of {at_s, do}");
  std::vector<ScenarioStep> out;
  for (const auto& s : steps) {
    if (!s.IsMap() || !s["at_s"] || !s["do"] || s.size() != 2) fail(s, "a step is {at_s: SECONDS, do: COMMAND}");
    ScenarioStep st;
    try {
      st.at_s = s["at_s"].as<double>();
      st.command = s["do"].as<std::string>();
    } catch (const YAML::Exception&) {
      fail(s, "at_s must be a number and do a command");
    }
    if (!(st.at_s >= 0.0)) fail(s["at_s"], "at_s must be >= 0");
    out.push_back(st);
  }
  return out;
}

CanSim::CanSim(CanSimOptions options, can::CanConfig config)
    : o_(std::move(options)),
      cfg_(std::move(config)),
      rng_(o_.seed),
      node_on_(cfg_.nodes.size(), true),
      heartbeat_on_(cfg_.nodes.size(), true),
      pressed_(cfg_.inputs.size(), false) {
  // Frame images: every input released; periodic devices' frames exist even without inputs.
  for (const auto& n : cfg_.nodes)
    if (n.liveness == can::NodeConfig::Liveness::Periodic) {
      can::CanFrame& f = images_[{n.id, n.extended}];
      f.id = n.id;
      f.extended = n.extended;
      f.dlc = std::max<std::uint8_t>(f.dlc, 1);
    }
  for (std::size_t i = 0; i < cfg_.inputs.size(); ++i) {
    const auto& in = cfg_.inputs[i];
    can::CanFrame& f = images_[{in.id, in.extended}];
    f.id = in.id;
    f.extended = in.extended;
    f.dlc = std::max<std::uint8_t>(f.dlc, static_cast<std::uint8_t>(in.byte + (in.analog ? in.size : 1)));
  }
  for (std::size_t i = 0; i < cfg_.inputs.size(); ++i) set_input(i, false, cfg_.inputs[i].release_at);
}

CanSim::~CanSim() {
  for (int c : clients_) ::close(c);
  if (listen_fd_ >= 0) {
    ::close(listen_fd_);
    ::unlink((o_.socketcan_dir + "/" + o_.interface + ".sock").c_str());
  }
  if (control_fd_ >= 0) {
    ::close(control_fd_);
    ::unlink(o_.control_socket.c_str());
  }
  if (log_) std::fclose(log_);
}

std::string CanSim::start() {
  start_us_ = monotonic_us();
  if (!o_.log_path.empty()) {
    log_ = std::fopen(o_.log_path.c_str(), "w");
    if (!log_) throw sys_error("cannot write the log " + o_.log_path);
  }
  if (!o_.control_socket.empty()) {
    sockaddr_un addr{};
    if (o_.control_socket.size() >= sizeof addr.sun_path) throw std::runtime_error("control socket path too long");
    control_fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    addr.sun_family = AF_UNIX;
    std::strncpy(addr.sun_path, o_.control_socket.c_str(), sizeof addr.sun_path - 1);
    ::unlink(o_.control_socket.c_str());
    if (control_fd_ < 0 || ::bind(control_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0)
      throw sys_error("control socket " + o_.control_socket);
  }
  at(start_us_, [this] { heartbeat_tick(); });
  at(start_us_, [this] { periodic_tick(); });
  if (!o_.socketcan_dir.empty()) {
    const std::string path = o_.socketcan_dir + "/" + o_.interface + ".sock";
    sockaddr_un addr{};
    if (path.size() >= sizeof addr.sun_path) throw std::runtime_error("bus socket path too long: " + path);
    listen_fd_ = ::socket(AF_UNIX, SOCK_SEQPACKET | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    addr.sun_family = AF_UNIX;
    std::strncpy(addr.sun_path, path.c_str(), sizeof addr.sun_path - 1);
    ::unlink(path.c_str());
    if (listen_fd_ < 0 || ::bind(listen_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 || ::listen(listen_fd_, 16) != 0)
      throw sys_error("bus socket " + path);
    return path;
  }
  pty_ = std::make_unique<PtyState>(o_.pty_link, o_.bind_over);
  pty_->link.plug();
  return pty_->link.slave_path();
}

void CanSim::at(std::int64_t t_us, std::function<void()> fn) { actions_.push({t_us, ++seq_, std::move(fn)}); }

void CanSim::schedule(double at_s, const std::string& text) { schedule_from_epoch(start_us_, at_s, text); }

void CanSim::schedule_from_epoch(std::int64_t epoch_mono_us, double at_s, const std::string& text) {
  at(epoch_mono_us + static_cast<std::int64_t>(at_s * 1e6), [this, text] {
    const std::string r = command(text);
    std::cerr << "arnav-can-sim: " << text << ": " << r << "\n";
  });
}

bool CanSim::bus_off() const { return monotonic_us() < bus_off_until_us_; }

void CanSim::send(const can::CanFrame& f) {
  if (bus_off() && !f.error) return;
  ++frames_sent_;
  if (log_) std::fprintf(log_, "%s\n", can::format_log_line({wall_us(), o_.interface, f}).c_str());
  if (listen_fd_ >= 0) {
    can_frame cf{};
    cf.can_id = f.error ? (f.id | CAN_ERR_FLAG) : f.extended ? (f.id | CAN_EFF_FLAG) : f.id;
    if (f.remote) cf.can_id |= CAN_RTR_FLAG;
    cf.len = f.dlc;
    std::memcpy(cf.data, f.data.data(), 8);
    for (std::size_t i = 0; i < clients_.size();) {
      if (::send(clients_[i], &cf, sizeof cf, MSG_NOSIGNAL | MSG_DONTWAIT) < 0 && errno != EAGAIN) {
        ::close(clients_[i]);
        clients_.erase(clients_.begin() + static_cast<std::ptrdiff_t>(i));
        continue;
      }
      ++i;
    }
    return;
  }
  if (f.error || !slcan_open_) return;  // slcan reports errors through F flags
  std::string line = can::slcan::encode_frame(f);
  if (drop_chars_ > 0) {
    --drop_chars_;
    line.erase(std::uniform_int_distribution<std::size_t>(0, line.size() - 1)(rng_), 1);
  }
  to_host(line);
}

void CanSim::send_error(std::uint32_t cls, std::uint8_t crtl) {
  can::CanFrame f;
  f.error = true;
  f.id = cls;
  f.dlc = 8;
  f.data[1] = crtl;
  send(f);
}

void CanSim::send_image(std::uint32_t id, bool ext) {
  for (std::size_t n = 0; n < cfg_.nodes.size(); ++n)
    if (!node_on_[n])
      for (const auto& in : cfg_.inputs)
        if (in.id == id && in.extended == ext && in.node == n) return;  // a silent device sends nothing
  send(images_[{id, ext}]);
}

void CanSim::set_input(std::size_t i, bool pressed, double value) {
  const auto& in = cfg_.inputs[i];
  can::CanFrame& f = images_[{in.id, in.extended}];
  pressed_[i] = pressed;
  const auto b = static_cast<std::size_t>(in.byte);
  if (in.analog) {
    const auto v = static_cast<std::uint32_t>(value);
    if (in.size == 1) f.data[b] = static_cast<std::uint8_t>(v);
    else if (in.big_endian) {
      f.data[b] = static_cast<std::uint8_t>(v >> 8);
      f.data[b + 1] = static_cast<std::uint8_t>(v);
    } else {
      f.data[b] = static_cast<std::uint8_t>(v);
      f.data[b + 1] = static_cast<std::uint8_t>(v >> 8);
    }
  } else {
    const bool bit = pressed == in.active_high;
    if (bit) f.data[b] = static_cast<std::uint8_t>(f.data[b] | (1u << in.bit));
    else f.data[b] = static_cast<std::uint8_t>(f.data[b] & ~(1u << in.bit));
  }
}

void CanSim::heartbeat_tick() {
  for (std::size_t n = 0; n < cfg_.nodes.size(); ++n) {
    const auto& nc = cfg_.nodes[n];
    if (nc.liveness != can::NodeConfig::Liveness::Heartbeat || !node_on_[n] || !heartbeat_on_[n]) continue;
    can::CanFrame f;
    f.id = nc.id;
    f.dlc = 1;
    f.data[0] = 0x05;  // operational
    send(f);
  }
  at(monotonic_us() + o_.heartbeat_period_ms * 1000, [this] { heartbeat_tick(); });
}

void CanSim::periodic_tick() {
  for (std::size_t n = 0; n < cfg_.nodes.size(); ++n) {
    const auto& nc = cfg_.nodes[n];
    if (nc.liveness != can::NodeConfig::Liveness::Periodic || !node_on_[n] || !heartbeat_on_[n]) continue;
    send(images_[{nc.id, nc.extended}]);
  }
  at(monotonic_us() + o_.periodic_period_ms * 1000, [this] { periodic_tick(); });
}

std::size_t CanSim::input_index(const std::string& name) const {
  for (std::size_t i = 0; i < cfg_.inputs.size(); ++i)
    if (cfg_.inputs[i].name == name) return i;
  return SIZE_MAX;
}

std::size_t CanSim::node_index(const std::string& name) const {
  for (std::size_t i = 0; i < cfg_.nodes.size(); ++i)
    if (cfg_.nodes[i].name == name) return i;
  return SIZE_MAX;
}

std::string CanSim::command(const std::string& text, bool dry_run) {
  const auto w = words(text);
  if (w.empty()) return "ERROR empty command";
  const std::string& c = w[0];
  auto need = [&](std::size_t n) { return w.size() == n; };
  auto num = [&](std::size_t k, double& v) { return k < w.size() && to_number(w[k], v); };
  const std::int64_t now = monotonic_us();
  if ((c == "press" || c == "release" || c == "value" || c == "bounce" || c == "train")) {
    if (w.size() < 2) return "ERROR " + c + " needs an input name";
    const std::size_t i = input_index(w[1]);
    if (i == SIZE_MAX) return "ERROR no input '" + w[1] + "' in the configuration";
    const auto& in = cfg_.inputs[i];
    const auto key = std::make_pair(in.id, in.extended);
    if (c == "press" || c == "release") {
      if (!need(2)) return "ERROR usage: " + c + " INPUT";
      if (dry_run) return "OK";
      set_input(i, c == "press", c == "press" ? in.press_at : in.release_at);
      send_image(key.first, key.second);
      return "OK";
    }
    if (c == "value") {
      double v = 0;
      if (!need(3) || !num(2, v) || !in.analog || v < 0 || v > (in.size == 1 ? 255 : 65535)) return "ERROR usage: value ANALOGUE_INPUT RAW";
      if (dry_run) return "OK";
      set_input(i, v >= in.press_at, v);
      send_image(key.first, key.second);
      return "OK";
    }
    double n = 0, ms = 0;
    if (!need(4) || !num(2, n) || !num(3, ms) || n < 1 || n > 1e6 || ms <= 0) return "ERROR usage: " + c + " INPUT N MS";
    if (c == "bounce") {
      // Chatter: the contact toggles n times, ms apart, and settles opposite to where it was.
      if (dry_run) return "OK";
      const bool target = !pressed_[i];
      const int toggles = static_cast<int>(n) * 2 + 1;
      for (int k = 0; k < toggles; ++k) {
        const bool state = k % 2 == 0 ? target : !target;
        at(now + static_cast<std::int64_t>(k * ms * 1000), [this, i, state, key] {
          set_input(i, state, state ? cfg_.inputs[i].press_at : cfg_.inputs[i].release_at);
          send_image(key.first, key.second);
        });
      }
      return "OK";
    }
    if (dry_run) return "OK";
    for (int k = 0; k < static_cast<int>(n); ++k) {
      const std::int64_t t = now + static_cast<std::int64_t>(k * ms * 1000);
      at(t, [this, i, key] {
        set_input(i, true, cfg_.inputs[i].press_at);
        send_image(key.first, key.second);
      });
      at(t + static_cast<std::int64_t>(ms * 500), [this, i, key] {
        set_input(i, false, cfg_.inputs[i].release_at);
        send_image(key.first, key.second);
      });
    }
    return "OK";
  }
  if (c == "node" || c == "heartbeat") {
    if (!need(3) || (w[2] != "on" && w[2] != "off")) return "ERROR usage: " + c + " DEVICE on|off";
    const std::size_t n = node_index(w[1]);
    if (n == SIZE_MAX) return "ERROR no device '" + w[1] + "' in the configuration";
    if (dry_run) return "OK";
    (c == "node" ? node_on_ : heartbeat_on_)[n] = w[2] == "on";
    return "OK";
  }
  if (c == "bus_off") {
    double s = 0;
    if (!need(2) || !num(1, s) || s <= 0 || s > 3600) return "ERROR usage: bus_off SECONDS";
    if (dry_run) return "OK";
    send_error(can::err::kBusOff, 0);
    bus_off_until_us_ = now + static_cast<std::int64_t>(s * 1e6);
    slcan_flags_ |= can::slcan::status::kBusError;
    at(bus_off_until_us_, [this] {
      slcan_flags_ &= static_cast<std::uint8_t>(~can::slcan::status::kBusError);
      send_error(can::err::kRestarted, 0);
    });
    return "OK";
  }
  if (c == "error_frames") {
    double n = 0;
    if (!need(2) || !num(1, n) || n < 1 || n > 100000) return "ERROR usage: error_frames N";
    if (dry_run) return "OK";
    for (int k = 0; k < static_cast<int>(n); ++k) send_error(0x008 | 0x080, 0);  // protocol violation, bus error
    send_error(can::err::kCrtl, can::err::kCrtlRxPassive | can::err::kCrtlTxPassive);
    slcan_flags_ |= can::slcan::status::kErrorPassive;
    at(now + 500'000, [this] {
      slcan_flags_ &= static_cast<std::uint8_t>(~can::slcan::status::kErrorPassive);
      send_error(can::err::kCrtl, can::err::kCrtlActive);
    });
    return "OK";
  }
  if (c == "garbage" || c == "drop_chars") {
    double n = 0;
    if (!need(2) || !num(1, n) || n < 1 || n > 1e6) return "ERROR usage: " + c + " N";
    if (!pty_) return "ERROR " + c + " is for the slcan path (the SocketCAN bus carries whole frames)";
    if (dry_run) return "OK";
    if (c == "drop_chars") {
      drop_chars_ += static_cast<int>(n);
    } else {
      std::string g;
      for (int k = 0; k < static_cast<int>(n); ++k) g += static_cast<char>(std::uniform_int_distribution<int>(0, 255)(rng_));
      to_host(g);
    }
    return "OK";
  }
  if (c == "flood") {
    double rate = 0, s = 0;
    if (!need(3) || !num(1, rate) || !num(2, s) || rate <= 0 || rate > 100000 || s <= 0 || s > 3600) return "ERROR usage: flood RATE SECONDS";
    if (dry_run) return "OK";
    const auto total = static_cast<std::int64_t>(rate * s);
    const double step_us = 1e6 / rate;
    // In 1 ms batches: the timer queue stays small.
    const std::int64_t per_ms = std::max<std::int64_t>(1, static_cast<std::int64_t>(rate / 1000.0));
    for (std::int64_t k = 0; k < total; k += per_ms) {
      at(now + static_cast<std::int64_t>(static_cast<double>(k) * step_us), [this, per_ms] {
        for (std::int64_t j = 0; j < per_ms; ++j) {
          can::CanFrame f;
          do f.id = std::uniform_int_distribution<std::uint32_t>(0, 0x6FF)(rng_);
          while (images_.count({f.id, false}));
          f.dlc = 8;
          for (auto& b : f.data) b = static_cast<std::uint8_t>(rng_());
          send(f);
        }
      });
    }
    return "OK";
  }
  if (c == "frame") {
    can::CanFrame f;
    if (!need(2) || can::parse_frame_text(w[1], f) != can::LogError::None) return "ERROR usage: frame ID#DATA (candump notation)";
    if (dry_run) return "OK";
    send(f);
    return "OK";
  }
  return "ERROR unknown command '" + c + "'; commands:\n" + commands_help();
}

void CanSim::to_host(const std::string& bytes) {
  if (out_.size() < (1u << 20)) out_ += bytes;
}

void CanSim::slcan_line(const std::string& line) {
  const char c = line.empty() ? 0 : line[0];
  using namespace can::slcan;
  if (c == 'C' && line.size() == 1) {
    to_host(slcan_open_ ? "\r" : "\a");
    slcan_open_ = false;
  } else if (c == 'O' && line.size() == 1) {
    if (slcan_open_ || slcan_bitrate_ < 0) to_host("\a");
    else {
      slcan_open_ = true;
      to_host("\r");
    }
  } else if (c == 'S' && line.size() == 2 && line[1] >= '0' && line[1] <= '8') {
    if (slcan_open_) to_host("\a");
    else {
      slcan_bitrate_ = line[1] - '0';
      to_host("\r");
    }
  } else if (c == 'V' && line.size() == 1) {
    to_host("V1013\r");
  } else if (c == 'N' && line.size() == 1) {
    to_host("NSIM1\r");
  } else if (c == 'F' && line.size() == 1) {
    if (!slcan_open_) to_host("\a");
    else {
      char b[8];
      std::snprintf(b, sizeof b, "F%02X\r", slcan_flags_);
      to_host(b);
    }
  } else if (c == 't' || c == 'T' || c == 'r' || c == 'R') {
    Reader r;
    r.feed(std::string_view(line + "\r"));
    Message m;
    if (!slcan_open_ || !r.next(m) || m.kind != Message::Kind::Frame) to_host("\a");
    else {
      if (log_) std::fprintf(log_, "%s\n", can::format_log_line({wall_us(), o_.interface, m.frame}).c_str());
      to_host(m.frame.extended ? "Z\r" : "z\r");
    }
  } else {
    to_host("\a");
  }
}

void CanSim::slcan_from_host(const char* data, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) {
    if (data[i] == '\r') {
      slcan_line(host_line_);
      host_line_.clear();
    } else if (host_line_.size() < 64) {
      host_line_ += data[i];
    }
  }
}

void CanSim::accept_clients() {
  for (;;) {
    const int c = ::accept4(listen_fd_, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
    if (c < 0) return;
    clients_.push_back(c);
    std::cerr << "arnav-can-sim: a CAN socket joined " << o_.interface << " (" << clients_.size() << " on the bus)\n";
  }
}

void CanSim::read_clients() {
  for (std::size_t i = 0; i < clients_.size(); ++i) {
    can_frame cf{};
    const ssize_t n = ::recv(clients_[i], &cf, sizeof cf, MSG_DONTWAIT);
    if (n == 0 || (n < 0 && errno != EAGAIN)) {
      ::close(clients_[i]);
      clients_.erase(clients_.begin() + static_cast<std::ptrdiff_t>(i));
      --i;
      continue;
    }
    if (n != static_cast<ssize_t>(sizeof cf)) continue;
    // A frame sent by one socket reaches every other one, as on a bus.
    for (std::size_t j = 0; j < clients_.size(); ++j)
      if (j != i) (void)::send(clients_[j], &cf, sizeof cf, MSG_NOSIGNAL | MSG_DONTWAIT);
    if (log_) {
      can::CanFrame f;
      f.error = cf.can_id & CAN_ERR_FLAG;
      f.extended = cf.can_id & CAN_EFF_FLAG;
      f.remote = cf.can_id & CAN_RTR_FLAG;
      f.id = f.extended ? cf.can_id & CAN_EFF_MASK : cf.can_id & CAN_SFF_MASK;
      f.dlc = cf.len > 8 ? 8 : cf.len;
      std::memcpy(f.data.data(), cf.data, 8);
      std::fprintf(log_, "%s\n", can::format_log_line({wall_us(), o_.interface, f}).c_str());
    }
  }
}

void CanSim::handle_control() {
  char buf[512];
  sockaddr_un from{};
  socklen_t len = sizeof from;
  const ssize_t n = ::recvfrom(control_fd_, buf, sizeof buf - 1, 0, reinterpret_cast<sockaddr*>(&from), &len);
  if (n <= 0) return;
  const std::string text(buf, static_cast<std::size_t>(n));
  const std::string answer = command(text);
  std::cerr << "arnav-can-sim: control: " << text << ": " << answer << "\n";
  if (len > sizeof(sa_family_t)) ::sendto(control_fd_, answer.data(), answer.size(), 0, reinterpret_cast<sockaddr*>(&from), len);
}

void CanSim::run(const volatile bool& stop) {
  std::vector<pollfd> fds;
  while (!stop) {
    std::int64_t now = monotonic_us();
    while (!actions_.empty() && actions_.top().at_us <= now) {
      Action a = actions_.top();
      actions_.pop();
      a.fn();
    }
    const int pty_fd = pty_ ? pty_->link.master_fd() : -1;
    if (pty_fd >= 0 && !out_.empty()) {
      const ssize_t w = ::write(pty_fd, out_.data(), out_.size());
      if (w > 0) out_.erase(0, static_cast<std::size_t>(w));
    }
    fds.clear();
    if (control_fd_ >= 0) fds.push_back({control_fd_, POLLIN, 0});
    if (listen_fd_ >= 0) fds.push_back({listen_fd_, POLLIN, 0});
    for (int c : clients_) fds.push_back({c, POLLIN, 0});
    if (pty_fd >= 0) fds.push_back({pty_fd, static_cast<short>(POLLIN | (out_.empty() ? 0 : POLLOUT)), 0});
    now = monotonic_us();
    std::int64_t wait = actions_.empty() ? 20'000 : std::clamp<std::int64_t>(actions_.top().at_us - now, 0, 20'000);
    timespec ts{0, static_cast<long>(wait * 1000)};
    if (::ppoll(fds.data(), fds.size(), &ts, nullptr) <= 0) continue;
    for (const auto& p : fds) {
      if (!(p.revents & (POLLIN | POLLHUP | POLLERR))) continue;
      if (p.fd == control_fd_) handle_control();
      else if (p.fd == listen_fd_) accept_clients();
      else if (p.fd == pty_fd) {
        char buf[512];
        const ssize_t n = ::read(pty_fd, buf, sizeof buf);
        if (n > 0) slcan_from_host(buf, static_cast<std::size_t>(n));
        else if (p.revents & POLLHUP) std::this_thread::sleep_for(std::chrono::milliseconds(1));  // host closed its end
      }
    }
    if (!clients_.empty()) read_clients();
  }
}

}  // namespace arnav::hil
