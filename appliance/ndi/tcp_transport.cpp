#include "appliance/ndi/tcp_transport.hpp"

#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

namespace arnav::ndi {
namespace {

std::string errno_text(int e) { return std::strerror(e); }

void set_int_option(int fd, int level, int name, int value) {
  (void)::setsockopt(fd, level, name, &value, sizeof value);  // best effort: a kernel without it still works
}

// Connects one address with a timeout; returns the socket or -1 with err set.
int connect_one(const addrinfo* ai, std::chrono::milliseconds timeout, int& err) {
  const int fd = ::socket(ai->ai_family, ai->ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, ai->ai_protocol);
  if (fd < 0) {
    err = errno;
    return -1;
  }
  if (::connect(fd, ai->ai_addr, ai->ai_addrlen) != 0 && errno != EINPROGRESS) {
    err = errno;
    ::close(fd);
    return -1;
  }
  pollfd p{fd, POLLOUT, 0};
  const int rc = ::poll(&p, 1, static_cast<int>(timeout.count()));
  if (rc <= 0) {
    err = rc == 0 ? ETIMEDOUT : errno;
    ::close(fd);
    return -1;
  }
  int so_error = 0;
  socklen_t len = sizeof so_error;
  ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &so_error, &len);
  if (so_error != 0) {
    err = so_error;
    ::close(fd);
    return -1;
  }
  return fd;
}

}  // namespace

TcpTransport::TcpTransport(TcpOptions options)
    : options_(std::move(options)), label_("tcp:" + options_.host + ":" + std::to_string(options_.port)) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* found = nullptr;
  const std::string service = std::to_string(options_.port);
  if (const int rc = ::getaddrinfo(options_.host.c_str(), service.c_str(), &hints, &found); rc != 0)
    throw PortError(label_ + ": cannot resolve host '" + options_.host + "': " + ::gai_strerror(rc) +
                    " (for an mDNS name such as P9-B0103.local check that avahi/nss-mdns is installed, or give the IP address)");
  int err = 0;
  for (const addrinfo* ai = found; ai && fd_ < 0; ai = ai->ai_next) fd_ = connect_one(ai, options_.connect_timeout, err);
  ::freeaddrinfo(found);
  if (fd_ < 0)
    throw PortError(label_ + ": cannot connect: " + errno_text(err) +
                    (err == ETIMEDOUT ? " after " + std::to_string(options_.connect_timeout.count()) + " ms" : std::string()) +
                    " (is the tracker powered, on this network, and is the port right? NDI's default is 8765)");
  set_int_option(fd_, IPPROTO_TCP, TCP_NODELAY, 1);
  set_int_option(fd_, SOL_SOCKET, SO_KEEPALIVE, 1);
  const int user_timeout_ms = static_cast<int>(options_.user_timeout.count());
  set_int_option(fd_, IPPROTO_TCP, TCP_KEEPIDLE, std::max(1, user_timeout_ms / 2000));
  set_int_option(fd_, IPPROTO_TCP, TCP_KEEPINTVL, 1);
  set_int_option(fd_, IPPROTO_TCP, TCP_KEEPCNT, 2);
  set_int_option(fd_, IPPROTO_TCP, TCP_USER_TIMEOUT, user_timeout_ms);
}

TcpTransport::~TcpTransport() {
  if (fd_ >= 0) ::close(fd_);
}

std::size_t TcpTransport::read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout) {
  pollfd p{fd_, POLLIN, 0};
  const int rc = ::poll(&p, 1, static_cast<int>(std::max<std::int64_t>(0, timeout.count())));
  if (rc < 0) {
    if (errno == EINTR) return 0;
    throw PortLost(label_ + ": poll failed: " + errno_text(errno));
  }
  if (rc == 0) return 0;
  if (p.revents & (POLLIN | POLLHUP | POLLERR)) {
    const ssize_t n = ::recv(fd_, buffer.data(), buffer.size(), 0);
    if (n > 0) return static_cast<std::size_t>(n);
    if (n < 0 && (errno == EAGAIN || errno == EINTR)) return 0;
    throw PortLost(label_ + ": " + (n == 0 ? std::string("the tracker closed the connection") : "receive failed: " + errno_text(errno)));
  }
  if (p.revents & POLLNVAL) throw PortLost(label_ + ": socket closed");
  return 0;
}

void TcpTransport::write(std::span<const std::uint8_t> bytes) {
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::send(fd_, bytes.data() + done, bytes.size() - done, MSG_NOSIGNAL);
    if (n > 0) {
      done += static_cast<std::size_t>(n);
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && errno == EAGAIN) {
      pollfd p{fd_, POLLOUT, 0};
      if (::poll(&p, 1, static_cast<int>(options_.user_timeout.count())) <= 0 || (p.revents & (POLLHUP | POLLERR | POLLNVAL)))
        throw PortLost(label_ + ": send stalled or connection closed");
      continue;
    }
    throw PortLost(label_ + ": send failed: " + errno_text(errno));
  }
}

void TcpTransport::drain_input() {
  std::uint8_t scratch[4096];
  for (;;) {
    const ssize_t n = ::recv(fd_, scratch, sizeof scratch, MSG_DONTWAIT);
    if (n <= 0) return;  // nothing waiting (or closed: the next read reports it)
  }
}

std::optional<TcpOptions> parse_tcp_address(const std::string& text) {
  if (text.rfind("tcp:", 0) != 0) return std::nullopt;
  const std::string rest = text.substr(4);
  TcpOptions o;
  o.port = kNdiTcpPort;
  std::string port;
  if (!rest.empty() && rest.front() == '[') {  // [IPv6] or [IPv6]:port
    const auto close = rest.find(']');
    if (close == std::string::npos) return std::nullopt;
    o.host = rest.substr(1, close - 1);
    if (close + 1 < rest.size()) {
      if (rest[close + 1] != ':') return std::nullopt;
      port = rest.substr(close + 2);
      if (port.empty()) return std::nullopt;
    }
  } else if (std::count(rest.begin(), rest.end(), ':') == 1) {  // host:port
    const auto colon = rest.find(':');
    o.host = rest.substr(0, colon);
    port = rest.substr(colon + 1);
    if (port.empty()) return std::nullopt;
  } else {
    o.host = rest;  // a name, an IPv4 address, or a bare IPv6 address
  }
  if (o.host.empty()) return std::nullopt;
  if (!port.empty()) {
    if (port.size() > 5 || port.find_first_not_of("0123456789") != std::string::npos) return std::nullopt;
    o.port = std::stoi(port);
    if (o.port < 1 || o.port > 65535) return std::nullopt;
  }
  return o;
}

}  // namespace arnav::ndi
