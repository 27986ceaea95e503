// Test-only LD_PRELOAD shim that gives the production SocketCAN code a CAN socket on
// machines whose kernel has no AF_CAN (docs/hil.md, docs/can.md). With
// ARNAV_HIL_CAN_DIR set:
// - socket(PF_CAN, SOCK_RAW, CAN_RAW) returns an AF_UNIX SOCK_SEQPACKET socket; every
//   datagram on it is one `struct can_frame` (16 bytes), as on a raw CAN socket;
// - ioctl(SIOCGIFINDEX) knows an interface NAME when DIR/NAME.sock exists (the simulated
//   bus, served by arnav-can-sim), else ENODEV as the kernel would say;
// - setsockopt(SOL_CAN_RAW, CAN_RAW_FILTER / CAN_RAW_ERR_FILTER) is stored and applied
//   here on receive with the kernel's rules (id & mask, CAN_INV_FILTER, error frames only
//   by class mask), so the production filter code is exercised; SOL_SOCKET options
//   (SO_TIMESTAMPNS: AF_UNIX stamps each datagram when it is sent) go to the real socket;
// - bind(sockaddr_can) connects to DIR/NAME.sock;
// - recvmsg/recv/recvfrom/read drop frames the filters reject and report the sender as
//   a sockaddr_can; write/send go out unchanged.
// Without ARNAV_HIL_CAN_DIR everything goes straight to the C library (EAFNOSUPPORT).
// Never linked into, or shipped with, the appliance.
#include <dlfcn.h>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdarg>
#include <cstdlib>
#include <cstring>
#include <mutex>

namespace {

constexpr int kMaxFd = 4096;
constexpr int kMaxFilters = CAN_RAW_FILTER_MAX;
constexpr int kMaxIfaces = 32;
constexpr int kFirstIndex = 1000;

struct FakeCan {
  int nfilters = 1;
  can_filter filters[kMaxFilters] = {{0, 0}};  // default: every frame
  can_err_mask_t err_mask = 0;
  int ifindex = 0;
};

std::atomic<FakeCan*> g_fake[kMaxFd];
std::mutex g_iface_mutex;
char g_ifaces[kMaxIfaces][IFNAMSIZ];
int g_nifaces = 0;

const char* can_dir() {
  const char* d = std::getenv("ARNAV_HIL_CAN_DIR");
  return d && *d ? d : nullptr;
}

FakeCan* fake(int fd) { return fd >= 0 && fd < kMaxFd ? g_fake[fd].load() : nullptr; }

template <typename F>
F real(const char* name) {
  return reinterpret_cast<F>(dlsym(RTLD_NEXT, name));
}

bool sock_path(const char* name, sockaddr_un& addr) {
  const char* dir = can_dir();
  if (!dir) return false;
  addr = sockaddr_un{};
  addr.sun_family = AF_UNIX;
  const int n = std::snprintf(addr.sun_path, sizeof addr.sun_path, "%s/%s.sock", dir, name);
  return n > 0 && static_cast<std::size_t>(n) < sizeof addr.sun_path;
}

int index_of(const char* name) {
  sockaddr_un addr;
  struct stat st;
  if (!sock_path(name, addr) || ::stat(addr.sun_path, &st) != 0 || !S_ISSOCK(st.st_mode)) return 0;
  std::lock_guard lock(g_iface_mutex);
  for (int i = 0; i < g_nifaces; ++i)
    if (std::strncmp(g_ifaces[i], name, IFNAMSIZ) == 0) return kFirstIndex + i;
  if (g_nifaces == kMaxIfaces) return 0;
  std::strncpy(g_ifaces[g_nifaces], name, IFNAMSIZ - 1);
  return kFirstIndex + g_nifaces++;
}

const char* name_of(int index) {
  std::lock_guard lock(g_iface_mutex);
  const int i = index - kFirstIndex;
  return i >= 0 && i < g_nifaces ? g_ifaces[i] : nullptr;
}

// The kernel's can_raw receive rules.
bool accept(const FakeCan& s, const can_frame& f) {
  if (f.can_id & CAN_ERR_FLAG) return (f.can_id & s.err_mask & CAN_ERR_MASK) != 0;
  for (int i = 0; i < s.nfilters; ++i) {
    const can_filter& flt = s.filters[i];
    const bool inv = flt.can_id & CAN_INV_FILTER;
    const canid_t id = flt.can_id & ~CAN_INV_FILTER;
    const bool match = (f.can_id & flt.can_mask) == (id & flt.can_mask);
    if (match != inv) return true;
  }
  return false;
}

using recvmsg_fn = ssize_t (*)(int, msghdr*, int);

ssize_t fake_recvmsg(int fd, FakeCan& s, msghdr* msg, int flags) {
  static const auto real_recvmsg = real<recvmsg_fn>("recvmsg");
  for (;;) {
    void* name = msg->msg_name;
    const socklen_t namelen = msg->msg_namelen;
    const std::size_t controllen = msg->msg_controllen;
    msg->msg_name = nullptr;
    msg->msg_namelen = 0;
    const ssize_t n = real_recvmsg(fd, msg, flags);
    msg->msg_name = name;
    if (n < 0) return n;
    if (n == 0) return 0;  // the bus went away: EOF, the caller treats it as lost
    can_frame f{};
    std::size_t copied = 0;
    for (std::size_t i = 0; i < msg->msg_iovlen && copied < sizeof f; ++i) {
      const std::size_t take = std::min(msg->msg_iov[i].iov_len, sizeof f - copied);
      std::memcpy(reinterpret_cast<char*>(&f) + copied, msg->msg_iov[i].iov_base, take);
      copied += take;
    }
    if (copied == sizeof f && !accept(s, f)) {
      msg->msg_controllen = controllen;
      continue;
    }
    if (name && namelen >= sizeof(sockaddr_can)) {
      sockaddr_can from{};
      from.can_family = AF_CAN;
      from.can_ifindex = s.ifindex;
      std::memcpy(name, &from, sizeof from);
      msg->msg_namelen = sizeof from;
    } else {
      msg->msg_namelen = 0;
    }
    return n;
  }
}

}  // namespace

extern "C" int socket(int domain, int type, int protocol) {
  static const auto real_socket = real<int (*)(int, int, int)>("socket");
  if (domain != PF_CAN || (type & 0xF) != SOCK_RAW || protocol != CAN_RAW || !can_dir()) return real_socket(domain, type, protocol);
  const int fd = real_socket(AF_UNIX, SOCK_SEQPACKET | (type & (SOCK_CLOEXEC | SOCK_NONBLOCK)), 0);
  if (fd < 0) return fd;
  if (fd >= kMaxFd) {
    ::close(fd);
    errno = EMFILE;
    return -1;
  }
  delete g_fake[fd].exchange(new FakeCan);
  return fd;
}

extern "C" int close(int fd) {
  static const auto real_close = real<int (*)(int)>("close");
  if (fd >= 0 && fd < kMaxFd) delete g_fake[fd].exchange(nullptr);
  return real_close(fd);
}

extern "C" int ioctl(int fd, unsigned long request, ...) {
  va_list ap;
  va_start(ap, request);
  void* arg = va_arg(ap, void*);
  va_end(ap);
  static const auto real_ioctl = real<int (*)(int, unsigned long, ...)>("ioctl");
  if (fake(fd) && request == SIOCGIFINDEX) {
    auto* ifr = static_cast<ifreq*>(arg);
    char name[IFNAMSIZ];
    std::memcpy(name, ifr->ifr_name, IFNAMSIZ);
    name[IFNAMSIZ - 1] = 0;
    const int index = index_of(name);
    if (index == 0) {
      errno = ENODEV;
      return -1;
    }
    ifr->ifr_ifindex = index;
    return 0;
  }
  return real_ioctl(fd, request, arg);
}

extern "C" int setsockopt(int fd, int level, int optname, const void* optval, socklen_t optlen) {
  static const auto real_setsockopt = real<int (*)(int, int, int, const void*, socklen_t)>("setsockopt");
  FakeCan* s = fake(fd);
  if (!s || level != SOL_CAN_RAW) return real_setsockopt(fd, level, optname, optval, optlen);
  switch (optname) {
    case CAN_RAW_FILTER: {
      if (optlen % sizeof(can_filter) != 0 || optlen / sizeof(can_filter) > kMaxFilters) {
        errno = EINVAL;
        return -1;
      }
      s->nfilters = static_cast<int>(optlen / sizeof(can_filter));
      if (s->nfilters > 0) std::memcpy(s->filters, optval, optlen);
      return 0;
    }
    case CAN_RAW_ERR_FILTER:
      if (optlen != sizeof(can_err_mask_t)) {
        errno = EINVAL;
        return -1;
      }
      std::memcpy(&s->err_mask, optval, sizeof s->err_mask);
      return 0;
    case CAN_RAW_LOOPBACK:
    case CAN_RAW_RECV_OWN_MSGS:
      return 0;  // the bus never echoes a sender's own frames
    default:
      errno = ENOPROTOOPT;
      return -1;
  }
}

extern "C" int bind(int fd, const sockaddr* addr, socklen_t len) {
  static const auto real_bind = real<int (*)(int, const sockaddr*, socklen_t)>("bind");
  static const auto real_connect = real<int (*)(int, const sockaddr*, socklen_t)>("connect");
  FakeCan* s = fake(fd);
  if (!s) return real_bind(fd, addr, len);
  if (len < sizeof(sockaddr_can) || addr->sa_family != AF_CAN) {
    errno = EINVAL;
    return -1;
  }
  const auto* can = reinterpret_cast<const sockaddr_can*>(addr);
  const char* name = name_of(can->can_ifindex);
  sockaddr_un un;
  if (!name || !sock_path(name, un)) {
    errno = ENODEV;
    return -1;
  }
  if (real_connect(fd, reinterpret_cast<sockaddr*>(&un), sizeof un) != 0) {
    errno = errno == ECONNREFUSED || errno == ENOENT ? ENETDOWN : errno;
    return -1;
  }
  s->ifindex = can->can_ifindex;
  return 0;
}

extern "C" ssize_t recvmsg(int fd, msghdr* msg, int flags) {
  static const auto real_recvmsg = real<recvmsg_fn>("recvmsg");
  FakeCan* s = fake(fd);
  return s ? fake_recvmsg(fd, *s, msg, flags) : real_recvmsg(fd, msg, flags);
}

extern "C" ssize_t recvfrom(int fd, void* buf, size_t len, int flags, sockaddr* from, socklen_t* fromlen) {
  static const auto real_recvfrom = real<ssize_t (*)(int, void*, size_t, int, sockaddr*, socklen_t*)>("recvfrom");
  FakeCan* s = fake(fd);
  if (!s) return real_recvfrom(fd, buf, len, flags, from, fromlen);
  iovec iov{buf, len};
  msghdr msg{};
  msg.msg_name = from;
  msg.msg_namelen = fromlen ? *fromlen : 0;
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  const ssize_t n = fake_recvmsg(fd, *s, &msg, flags);
  if (n >= 0 && fromlen) *fromlen = msg.msg_namelen;
  return n;
}

extern "C" ssize_t recv(int fd, void* buf, size_t len, int flags) { return recvfrom(fd, buf, len, flags, nullptr, nullptr); }

extern "C" ssize_t read(int fd, void* buf, size_t len) {
  static const auto real_read = real<ssize_t (*)(int, void*, size_t)>("read");
  if (!fake(fd)) return real_read(fd, buf, len);
  return recvfrom(fd, buf, len, 0, nullptr, nullptr);
}
