#include "appliance/can/socketcan_transport.hpp"

#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "protocol/clock.hpp"

namespace arnav::can {
namespace {

static_assert(err::kBusOff == CAN_ERR_BUSOFF && err::kRestarted == CAN_ERR_RESTARTED && err::kCrtl == CAN_ERR_CRTL &&
              err::kCrtlRxPassive == CAN_ERR_CRTL_RX_PASSIVE && err::kCrtlActive == CAN_ERR_CRTL_ACTIVE,
              "error class constants must match linux/can/error.h");

std::string errno_text(int e) { return std::strerror(e); }

}  // namespace

SocketCanTransport::SocketCanTransport(std::string interface, const std::vector<std::pair<std::uint32_t, bool>>& ids,
                                       std::uint32_t error_mask)
    : interface_(std::move(interface)) {
  fd_ = ::socket(PF_CAN, SOCK_RAW | SOCK_CLOEXEC, CAN_RAW);
  if (fd_ < 0) {
    const int e = errno;
    if (e == EAFNOSUPPORT || e == EPROTONOSUPPORT)
      throw CanUnavailable(CanUnavailable::Kind::NoAfCan,
                           interface_ + ": this kernel has no SocketCAN (socket(PF_CAN, SOCK_RAW, CAN_RAW): " + errno_text(e) +
                               "); load the can and can_raw modules, or use an slcan adapter (interface: slcan:/dev/ttyUSB0)");
    throw CanUnavailable(CanUnavailable::Kind::Refused, interface_ + ": cannot create a CAN socket: " + errno_text(e));
  }
  auto fail = [&](CanUnavailable::Kind kind, const std::string& what) {
    ::close(fd_);
    fd_ = -1;
    throw CanUnavailable(kind, interface_ + ": " + what);
  };
  ifreq ifr{};
  std::strncpy(ifr.ifr_name, interface_.c_str(), IFNAMSIZ - 1);
  if (::ioctl(fd_, SIOCGIFINDEX, &ifr) < 0) {
    const int e = errno;
    fail(e == ENODEV ? CanUnavailable::Kind::NoInterface : CanUnavailable::Kind::Refused,
         "no such CAN interface (" + errno_text(e) + "); list them with `ip -details link show type can` (vcan for tests: `ip link add dev vcan0 type vcan`)");
  }
  ifindex_ = ifr.ifr_ifindex;

  std::vector<can_filter> filters;
  for (const auto& [id, ext] : ids)
    filters.push_back({ext ? (id | CAN_EFF_FLAG) : id, ext ? (CAN_EFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG) : (CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG)});
  if (!filters.empty() && ::setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_FILTER, filters.data(),
                                       static_cast<socklen_t>(filters.size() * sizeof(can_filter))) < 0)
    fail(CanUnavailable::Kind::Refused, "cannot set receive filters: " + errno_text(errno));
  can_err_mask_t mask = error_mask;
  if (::setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &mask, sizeof mask) < 0)
    fail(CanUnavailable::Kind::Refused, "cannot ask for error frames: " + errno_text(errno));
  const int on = 1;
  if (::setsockopt(fd_, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof on) < 0)
    fail(CanUnavailable::Kind::Refused, "cannot enable receive timestamps: " + errno_text(errno));
  (void)::setsockopt(fd_, SOL_SOCKET, SO_RXQ_OVFL, &on, sizeof on);  // drop counts: optional

  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifindex_;
  if (::bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0) {
    const int e = errno;
    fail(e == ENODEV || e == ENETDOWN ? CanUnavailable::Kind::NoInterface : CanUnavailable::Kind::Refused,
         "cannot bind the CAN socket: " + errno_text(e) + (e == ENETDOWN ? " (bring it up: ip link set " + interface_ + " up)" : ""));
  }
}

SocketCanTransport::~SocketCanTransport() {
  if (fd_ >= 0) ::close(fd_);
}

bool SocketCanTransport::receive(Received& out, std::chrono::microseconds timeout) {
  pollfd p{fd_, POLLIN, 0};
  // Microsecond timeout: a debounce deadline must not wait for the next millisecond.
  const std::int64_t us = std::max<std::int64_t>(0, timeout.count());
  const timespec wait{static_cast<time_t>(us / 1'000'000), static_cast<long>((us % 1'000'000) * 1000)};
  const int rc = ::ppoll(&p, 1, &wait, nullptr);
  if (rc < 0) {
    if (errno == EINTR) return false;
    throw CanLinkLost(interface_ + ": poll failed: " + errno_text(errno));
  }
  if (rc == 0) return false;
  if (p.revents & (POLLERR | POLLHUP | POLLNVAL)) {
    if (!(p.revents & POLLIN)) throw CanLinkLost(interface_ + ": the CAN interface went away");
  }
  can_frame cf{};
  sockaddr_can from{};
  iovec iov{&cf, sizeof cf};
  alignas(cmsghdr) char control[CMSG_SPACE(sizeof(timespec)) + CMSG_SPACE(sizeof(std::uint32_t)) + 64];
  msghdr msg{};
  msg.msg_name = &from;
  msg.msg_namelen = sizeof from;
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  msg.msg_control = control;
  msg.msg_controllen = sizeof control;
  const ssize_t n = ::recvmsg(fd_, &msg, MSG_DONTWAIT);
  out.receive_mono_us = monotonic_us();
  if (n < 0) {
    if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) return false;
    throw CanLinkLost(interface_ + ": read failed: " + errno_text(errno) + (errno == ENETDOWN ? " (interface down)" : ""));
  }
  if (n == 0) throw CanLinkLost(interface_ + ": the CAN socket was closed");
  if (static_cast<std::size_t>(n) != sizeof(can_frame)) return false;  // CAN FD or short: not ours
  out.device_wall_us = -1;
  for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c; c = CMSG_NXTHDR(&msg, c)) {
    if (c->cmsg_level != SOL_SOCKET) continue;
    if (c->cmsg_type == SO_TIMESTAMPNS) {
      timespec ts{};
      std::memcpy(&ts, CMSG_DATA(c), sizeof ts);
      out.device_wall_us = static_cast<std::int64_t>(ts.tv_sec) * 1'000'000 + ts.tv_nsec / 1000;
    } else if (c->cmsg_type == SO_RXQ_OVFL) {
      std::uint32_t drops = 0;
      std::memcpy(&drops, CMSG_DATA(c), sizeof drops);
      counters_.overruns += static_cast<std::int64_t>(drops - last_drops_);
      last_drops_ = drops;
    }
  }
  CanFrame& f = out.frame;
  f = CanFrame{};
  f.error = (cf.can_id & CAN_ERR_FLAG) != 0;
  f.extended = !f.error && (cf.can_id & CAN_EFF_FLAG) != 0;
  f.remote = !f.error && (cf.can_id & CAN_RTR_FLAG) != 0;
  f.id = f.error ? (cf.can_id & CAN_ERR_MASK) : f.extended ? (cf.can_id & CAN_EFF_MASK) : (cf.can_id & CAN_SFF_MASK);
  f.dlc = cf.len > 8 ? 8 : cf.len;
  std::memcpy(f.data.data(), cf.data, 8);
  if (f.error) counters_.error_frames += 1;
  else counters_.frames += 1;
  return true;
}

void SocketCanTransport::send(const CanFrame& f) {
  can_frame cf{};
  cf.can_id = f.extended ? (f.id & CAN_EFF_MASK) | CAN_EFF_FLAG : (f.id & CAN_SFF_MASK);
  if (f.remote) cf.can_id |= CAN_RTR_FLAG;
  cf.len = f.dlc > 8 ? 8 : f.dlc;
  std::memcpy(cf.data, f.data.data(), 8);
  const ssize_t n = ::write(fd_, &cf, sizeof cf);
  if (n != static_cast<ssize_t>(sizeof cf))
    throw CanLinkLost(interface_ + ": write failed: " + (n < 0 ? errno_text(errno) : std::string("short write")));
}

}  // namespace arnav::can
