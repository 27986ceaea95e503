#include "hil_tests/polaris_sim/pty_link.hpp"

#include <fcntl.h>
#include <sys/mount.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <stdexcept>

namespace arnav::hil {
namespace {
std::runtime_error sys_error(const std::string& what) { return std::runtime_error(what + ": " + std::strerror(errno)); }
}  // namespace

PtyLink::PtyLink(std::string link_path, std::string bind_over) : link_path_(std::move(link_path)), bind_over_(std::move(bind_over)) {}

PtyLink::~PtyLink() {
  unplug();
  if (guarded_) ::umount2(bind_over_.c_str(), MNT_DETACH);
}

void PtyLink::plug() {
  if (plugged()) return;
  master_fd_ = posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (master_fd_ < 0) throw sys_error("posix_openpt");
  if (grantpt(master_fd_) != 0 || unlockpt(master_fd_) != 0) throw sys_error("grantpt/unlockpt");
  char name[128];
  if (ptsname_r(master_fd_, name, sizeof name) != 0) throw sys_error("ptsname_r");
  slave_path_ = name;
  slave_fd_ = ::open(name, O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (slave_fd_ < 0) throw sys_error("open " + slave_path_);
  // A Polaris after power-up: 9600 8N1, no handshake, raw bytes (no CR/LF translation).
  termios tio{};
  if (tcgetattr(slave_fd_, &tio) != 0) throw sys_error("tcgetattr " + slave_path_);
  cfmakeraw(&tio);
  tio.c_cflag |= CLOCAL | CREAD;
  cfsetispeed(&tio, B9600);
  cfsetospeed(&tio, B9600);
  if (tcsetattr(slave_fd_, TCSANOW, &tio) != 0) throw sys_error("tcsetattr " + slave_path_);

  ::unlink(link_path_.c_str());
  if (::symlink(slave_path_.c_str(), link_path_.c_str()) != 0) throw sys_error("symlink " + link_path_ + " -> " + slave_path_);
  if (!bind_over_.empty()) {
    // Underneath the pty lies a /dev/null guard for the whole run: while unplugged (and in
    // the instant of re-plugging) the node is /dev/null, which no serial library can
    // configure, and never the real device below (on these machines ttyS0 is the console).
    if (!guarded_) {
      if (::mount("/dev/null", bind_over_.c_str(), nullptr, MS_BIND, nullptr) != 0)
        throw sys_error("bind mount /dev/null over " + bind_over_ + " (needs root in a private mount namespace)");
      guarded_ = true;
    }
    if (::mount(slave_path_.c_str(), bind_over_.c_str(), nullptr, MS_BIND, nullptr) != 0)
      throw sys_error("bind mount " + slave_path_ + " over " + bind_over_ + " (needs root in a private mount namespace)");
    bound_ = true;
  }
}


void PtyLink::unplug() {
  if (!plugged()) return;
  ::unlink(link_path_.c_str());
  if (bound_) {
    // Detach the pty's mount (lazily: the host may still hold the node open); the guard
    // below shows through.
    ::umount2(bind_over_.c_str(), MNT_DETACH);
    bound_ = false;
  }
  ::close(slave_fd_);
  ::close(master_fd_);
  slave_fd_ = master_fd_ = -1;
}

int PtyLink::host_baud() const { return slave_fd_ >= 0 ? tty_baud(slave_fd_) : 0; }

}  // namespace arnav::hil
