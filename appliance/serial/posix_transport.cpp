#include "appliance/serial/posix_transport.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace arnav::ndi {
namespace {

speed_t speed_for(int baud) {
  switch (baud) {
    case 9600: return B9600;
    case 19200: return B19200;
    case 38400: return B38400;
    case 57600: return B57600;
    case 115200: return B115200;
    case 230400: return B230400;
    case 921600: return B921600;
    default: return 0;
  }
}

std::string errno_text() { return std::strerror(errno); }

}  // namespace

PosixTransport::PosixTransport(std::string path) : path_(std::move(path)) {
  fd_ = ::open(path_.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd_ < 0) throw PortError(path_ + ": cannot open: " + errno_text());
  termios tio{};
  if (::tcgetattr(fd_, &tio) != 0) {
    const std::string err = errno_text();
    ::close(fd_);
    throw PortError(path_ + ": not a terminal: " + err);
  }
  ::cfmakeraw(&tio);
  tio.c_cflag |= CLOCAL | CREAD;
  tio.c_cflag &= ~(CSTOPB | PARENB | CRTSCTS);
  tio.c_cc[VMIN] = 0;
  tio.c_cc[VTIME] = 0;
  ::cfsetispeed(&tio, B9600);
  ::cfsetospeed(&tio, B9600);
  if (::tcsetattr(fd_, TCSANOW, &tio) != 0) {
    const std::string err = errno_text();
    ::close(fd_);
    throw PortError(path_ + ": cannot configure: " + err);
  }
}

PosixTransport::~PosixTransport() {
  if (fd_ >= 0) ::close(fd_);
}

std::size_t PosixTransport::read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout) {
  pollfd p{fd_, POLLIN, 0};
  int rc = ::poll(&p, 1, static_cast<int>(timeout.count()));
  if (rc < 0) {
    if (errno == EINTR) return 0;
    throw PortLost(path_ + ": poll failed: " + errno_text());
  }
  if (rc == 0) return 0;
  if (p.revents & POLLIN) {
    ssize_t n = ::read(fd_, buffer.data(), buffer.size());
    if (n > 0) return static_cast<std::size_t>(n);
    if (n < 0 && (errno == EAGAIN || errno == EINTR)) return 0;
    throw PortLost(path_ + ": read failed: " + (n == 0 ? std::string("end of file") : errno_text()));
  }
  if (p.revents & (POLLHUP | POLLERR | POLLNVAL)) throw PortLost(path_ + ": the other side closed the line");
  return 0;
}

void PosixTransport::write(std::span<const std::uint8_t> bytes) {
  std::size_t done = 0;
  while (done < bytes.size()) {
    ssize_t n = ::write(fd_, bytes.data() + done, bytes.size() - done);
    if (n > 0) {
      done += static_cast<std::size_t>(n);
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && errno == EAGAIN) {
      pollfd p{fd_, POLLOUT, 0};
      if (::poll(&p, 1, 1000) <= 0 || (p.revents & (POLLHUP | POLLERR | POLLNVAL)))
        throw PortLost(path_ + ": write stalled or line closed");
      continue;
    }
    throw PortLost(path_ + ": write failed: " + errno_text());
  }
}

void PosixTransport::set_baud(int baud) {
  const speed_t s = speed_for(baud);
  if (s == 0) throw PortError(path_ + ": baud rate " + std::to_string(baud) + " is not supported by termios");
  termios tio{};
  if (::tcgetattr(fd_, &tio) != 0) throw PortLost(path_ + ": tcgetattr failed: " + errno_text());
  ::cfsetispeed(&tio, s);
  ::cfsetospeed(&tio, s);
  if (::tcsetattr(fd_, TCSADRAIN, &tio) != 0) throw PortLost(path_ + ": tcsetattr failed: " + errno_text());
}

void PosixTransport::send_break(std::chrono::milliseconds duration) {
  // tcsendbreak's duration is implementation defined; hold it explicitly instead.
  // A pty accepts and swallows it; the session copes with a missing RESET.
  if (::ioctl(fd_, TIOCSBRK) != 0) return;
  ::usleep(static_cast<useconds_t>(duration.count() * 1000));
  ::ioctl(fd_, TIOCCBRK);
}

bool PosixTransport::supports_baud(int baud) const { return speed_for(baud) != 0; }

void PosixTransport::drain_input() { ::tcflush(fd_, TCIFLUSH); }

}  // namespace arnav::ndi
