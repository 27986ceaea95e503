// Test-only LD_PRELOAD shim that lets the production libserialport path run on a
// pseudo-terminal (see docs/machine-notes.md and docs/hil.md):
// - a pty rejects the modem-line ioctls (TIOCMGET/TIOCMSET/TIOCMBIS/TIOCMBIC) with ENOTTY,
//   which makes sp_open fail: the shim keeps per-fd modem bits and answers them;
// - a pty swallows a serial break: the shim reports TIOCSBRK ("on"), TIOCCBRK ("off") and
//   TCSBRK/tcsendbreak ("pulse") as datagrams to the simulator's break socket, named by
//   the environment variable ARNAV_HIL_BREAK_SOCKET.
// Only pty slave fds (Unix98 pty majors 136-143) are touched; everything else goes
// straight to the C library. Never linked into, or shipped with, the appliance.
#include <dlfcn.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <sys/un.h>
#include <termios.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace {

constexpr int kMaxFd = 4096;
constexpr int kDefaultModem = TIOCM_DTR | TIOCM_RTS | TIOCM_CTS | TIOCM_DSR | TIOCM_CD;
std::atomic<int> g_modem[kMaxFd];
std::atomic<bool> g_modem_known[kMaxFd];
std::atomic<bool> g_warned{false};

bool is_pty_slave(int fd) {
  struct stat st;
  if (fd < 0 || fstat(fd, &st) != 0 || !S_ISCHR(st.st_mode)) return false;
  const unsigned m = major(st.st_rdev);
  return m >= 136 && m <= 143;
}

int& modem_slot_init(int fd) {
  static thread_local int scratch;
  if (fd >= kMaxFd) return scratch = kDefaultModem;
  if (!g_modem_known[fd].exchange(true)) g_modem[fd].store(kDefaultModem);
  scratch = g_modem[fd].load();
  return scratch;
}

void report_break(const char* what) {
  const char* path = std::getenv("ARNAV_HIL_BREAK_SOCKET");
  if (path == nullptr || *path == 0) {
    if (!g_warned.exchange(true))
      std::fprintf(stderr, "serial_shim: break on a pty with no ARNAV_HIL_BREAK_SOCKET set: nobody is told\n");
    return;
  }
  const int saved_errno = errno;
  const int s = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (s >= 0) {
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strncpy(addr.sun_path, path, sizeof addr.sun_path - 1);
    sendto(s, what, std::strlen(what), 0, reinterpret_cast<sockaddr*>(&addr), sizeof addr);
    close(s);
  }
  errno = saved_errno;
}

using ioctl_fn = int (*)(int, unsigned long, ...);
using tcsendbreak_fn = int (*)(int, int);

}  // namespace

extern "C" int ioctl(int fd, unsigned long request, ...) {
  va_list ap;
  va_start(ap, request);
  void* arg = va_arg(ap, void*);
  va_end(ap);
  static const auto real = reinterpret_cast<ioctl_fn>(dlsym(RTLD_NEXT, "ioctl"));
  switch (request) {
    case TIOCMGET:
    case TIOCMSET:
    case TIOCMBIS:
    case TIOCMBIC: {
      if (!is_pty_slave(fd)) break;
      int bits = modem_slot_init(fd);
      if (request == TIOCMGET) {
        *static_cast<int*>(arg) = bits;
        return 0;
      }
      const int v = *static_cast<const int*>(arg);
      if (request == TIOCMSET) bits = v;
      if (request == TIOCMBIS) bits |= v;
      if (request == TIOCMBIC) bits &= ~v;
      if (fd < kMaxFd) g_modem[fd].store(bits);
      return 0;
    }
    case TIOCSBRK:
      if (!is_pty_slave(fd)) break;
      report_break("on");
      return 0;
    case TIOCCBRK:
      if (!is_pty_slave(fd)) break;
      report_break("off");
      return 0;
    case TCSBRK:
    case TCSBRKP:
      // TCSBRK with a non-zero argument is tcdrain, not a break.
      if (arg != nullptr || !is_pty_slave(fd)) break;
      report_break("pulse");
      return 0;
    default:
      break;
  }
  return real(fd, request, arg);
}

extern "C" int tcsendbreak(int fd, int duration) {
  static const auto real = reinterpret_cast<tcsendbreak_fn>(dlsym(RTLD_NEXT, "tcsendbreak"));
  if (is_pty_slave(fd)) {
    report_break("pulse");
    return 0;
  }
  return real(fd, duration);
}
