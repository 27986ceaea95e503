#pragma once
// The simulator's end of the virtual serial cable: a pseudo-terminal whose slave is
// published as a symlink (the agreed `--pty-link PATH`) and, on the HIL bench, also
// bind-mounted over a real tty node (e.g. /dev/ttyS0) inside a private mount namespace so
// that libserialport, which wants a /sys/class/tty entry, opens it unmodified.
// "Unplugging" closes the pty and makes the port vanish; "plugging" makes a new one.
#include <string>

namespace arnav::hil {

class PtyLink {
 public:
  PtyLink(std::string link_path, std::string bind_over);
  ~PtyLink();
  PtyLink(const PtyLink&) = delete;
  PtyLink& operator=(const PtyLink&) = delete;

  // Creates the pty (raw, 9600 8N1), the symlink and the bind mount. Throws on failure.
  void plug();
  // Closes the pty; the symlink is removed and the bind target shows /dev/null (which a
  // serial library cannot configure), so opening the port fails until plug().
  void unplug();
  bool plugged() const { return master_fd_ >= 0; }

  int master_fd() const { return master_fd_; }
  const std::string& slave_path() const { return slave_path_; }
  // Baud rate the host set on its end (master and slave share termios); 0 if unknown.
  int host_baud() const;

 private:
  std::string link_path_;
  std::string bind_over_;
  std::string slave_path_;
  int master_fd_ = -1;
  int slave_fd_ = -1;  // held open so host close/reopen keeps termios and no EIO on master
  bool bound_ = false;    // the pty is mounted over bind_over_
  bool guarded_ = false;  // the /dev/null guard is mounted over bind_over_
};

// Reads the output baud of a tty fd via TCGETS2 (handles non-standard rates such as
// 1228739). Returns 0 on failure.
int tty_baud(int fd);

}  // namespace arnav::hil
