#include "hil_tests/bench/control_client.hpp"

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <iostream>

namespace arnav::hil {

int send_control_command(const std::string& program, const std::string& socket_path, const std::string& command,
                         const std::string& no_simulator_hint) {
  const std::string who = program + " inject: ";
  const int fd = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  sockaddr_un me{}, sim{};
  me.sun_family = sim.sun_family = AF_UNIX;
  // Autobind an abstract address so the simulator can answer.
  if (fd < 0 || ::bind(fd, reinterpret_cast<sockaddr*>(&me), sizeof(sa_family_t)) != 0) {
    std::cerr << who << "cannot create a socket: " << std::strerror(errno) << "\n";
    if (fd >= 0) ::close(fd);
    return 1;
  }
  if (socket_path.size() >= sizeof sim.sun_path) {
    std::cerr << who << "socket path too long\n";
    ::close(fd);
    return 2;
  }
  std::strncpy(sim.sun_path, socket_path.c_str(), sizeof sim.sun_path - 1);
  if (::sendto(fd, command.data(), command.size(), 0, reinterpret_cast<sockaddr*>(&sim), sizeof sim) < 0) {
    std::cerr << who << "no simulator at " << socket_path << " (" << std::strerror(errno) << ")" << no_simulator_hint << "\n";
    ::close(fd);
    return 1;
  }
  pollfd p{fd, POLLIN, 0};
  if (::poll(&p, 1, 3000) <= 0) {
    std::cerr << who << "no answer from " << socket_path << " within 3 s\n";
    ::close(fd);
    return 1;
  }
  char buf[2048];
  const ssize_t n = ::recv(fd, buf, sizeof buf - 1, 0);
  ::close(fd);
  const std::string answer(buf, n > 0 ? static_cast<std::size_t>(n) : 0);
  std::cout << answer << std::endl;
  return answer == "OK" ? 0 : 1;
}

}  // namespace arnav::hil
