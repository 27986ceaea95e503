// PosixTransport on a real pseudo-terminal pair (what the bench simulator provides).
#include <gtest/gtest.h>

#include <fcntl.h>
#include <termios.h>
#include <unistd.h>

#include <cstdlib>
#include <algorithm>
#include <string>

#include "appliance/serial/posix_transport.hpp"

namespace arnav::ndi {
namespace {

using namespace std::chrono_literals;

struct Pty {
  int master = -1;
  std::string slave;
  Pty() {
    master = ::posix_openpt(O_RDWR | O_NOCTTY);
    if (master < 0 || ::grantpt(master) != 0 || ::unlockpt(master) != 0) throw std::runtime_error("no pty");
    slave = ::ptsname(master);
  }
  ~Pty() {
    if (master >= 0) ::close(master);
  }
};

TEST(PosixTransport, ReadWriteBaudAndLoss) {
  Pty pty;
  PosixTransport t(pty.slave);
  EXPECT_EQ(t.name(), pty.slave);

  const std::string reply = "OKAYA896\r";
  ASSERT_EQ(::write(pty.master, reply.data(), reply.size()), static_cast<ssize_t>(reply.size()));
  std::uint8_t buf[64];
  std::string got;
  for (int i = 0; i < 10 && got.size() < reply.size(); ++i) {
    const std::size_t n = t.read(buf, 200ms);
    got.append(reinterpret_cast<char*>(buf), n);
  }
  EXPECT_EQ(got, reply);
  EXPECT_EQ(t.read(buf, 20ms), 0u);  // nothing more: timeout

  const std::string cmd = "INIT:E3A5\r";
  t.write(std::span(reinterpret_cast<const std::uint8_t*>(cmd.data()), cmd.size()));
  char in[64];
  ssize_t n = 0;
  for (int i = 0; i < 50 && n <= 0; ++i) {
    n = ::read(pty.master, in, sizeof in);
    if (n <= 0) ::usleep(2000);
  }
  EXPECT_EQ(std::string(in, static_cast<std::size_t>(std::max<ssize_t>(n, 0))), cmd);

  // Master and slave share termios: the peer sees the rate the host set.
  t.set_baud(115200);
  termios tio{};
  ASSERT_EQ(::tcgetattr(pty.master, &tio), 0);
  EXPECT_EQ(::cfgetospeed(&tio), static_cast<speed_t>(B115200));
  EXPECT_TRUE(t.supports_baud(921600));
  EXPECT_FALSE(t.supports_baud(14400));
  EXPECT_THROW(t.set_baud(14400), PortError);
  t.send_break(1ms);  // swallowed by a pty; must not fail
  t.drain_input();

  ::close(pty.master);  // the simulator went away
  pty.master = -1;
  EXPECT_THROW(
      {
        for (int i = 0; i < 5; ++i) t.read(buf, 50ms);
      },
      PortLost);
}

TEST(PosixTransport, MissingPathNamesIt) {
  try {
    PosixTransport t("/dev/arnav-no-such-tty");
    ADD_FAILURE();
  } catch (const PortError& e) {
    EXPECT_NE(std::string(e.what()).find("/dev/arnav-no-such-tty"), std::string::npos);
  }
  EXPECT_THROW(PosixTransport("/dev/null"), PortError);  // not a terminal
}

}  // namespace
}  // namespace arnav::ndi
