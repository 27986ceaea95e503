#include "hil_tests/bench/namespaces.hpp"

#include <sched.h>
#include <sys/mount.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <stdexcept>

namespace arnav::hil {

std::string enter_bench_namespaces() {
  static std::string result = [] {
    if (::geteuid() != 0) return std::string("needs root (unshare of mount and network namespaces); run the HIL suite as root");
    if (::unshare(CLONE_NEWNS | CLONE_NEWNET) != 0)
      return std::string("unshare(CLONE_NEWNS|CLONE_NEWNET) failed: ") + std::strerror(errno) +
             " (containers may forbid namespaces)";
    if (::mount(nullptr, "/", nullptr, MS_REC | MS_PRIVATE, nullptr) != 0)
      return std::string("cannot make / private in the new mount namespace: ") + std::strerror(errno);
    // Loopback only; multicast (LCM udpm) goes to lo. There is no other interface here.
    if (std::system("ip link set lo up && ip route add 224.0.0.0/4 dev lo") != 0)
      return std::string("cannot bring up lo / add the multicast route (is iproute2 installed?)");
    return std::string();
  }();
  return result;
}

std::string make_temp_dir(const std::string& prefix) {
  std::string tmpl = "/tmp/" + prefix + "-XXXXXX";
  if (::mkdtemp(tmpl.data()) == nullptr) throw std::runtime_error("mkdtemp " + tmpl + ": " + std::strerror(errno));
  return tmpl;
}

}  // namespace arnav::hil
