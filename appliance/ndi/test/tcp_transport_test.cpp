// TcpTransport against a real socket on 127.0.0.1 (loopback only).
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include "appliance/ndi/tcp_transport.hpp"

namespace arnav::ndi {
namespace {

// A listening socket on 127.0.0.1 with a free port.
struct Listener {
  int fd = -1;
  int port = 0;
  Listener() {
    fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 || ::listen(fd, 1) != 0) throw std::runtime_error("listen");
    socklen_t len = sizeof a;
    ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
    port = ntohs(a.sin_port);
  }
  ~Listener() { ::close(fd); }
  int accept_one() const { return ::accept(fd, nullptr, nullptr); }
};

TcpOptions loopback(int port) {
  TcpOptions o;
  o.host = "127.0.0.1";
  o.port = port;
  o.connect_timeout = std::chrono::milliseconds(2000);
  return o;
}

TEST(TcpTransport, BytesGoBothWaysAndDrainDiscardsWhatWaits) {
  Listener l;
  TcpTransport t(loopback(l.port));
  EXPECT_TRUE(t.is_network());
  EXPECT_EQ(t.name(), "tcp:127.0.0.1:" + std::to_string(l.port));
  const int peer = l.accept_one();
  ASSERT_GE(peer, 0);
  const std::string cmd = "INIT:E3A5\r";
  t.write(std::span(reinterpret_cast<const std::uint8_t*>(cmd.data()), cmd.size()));
  char got[64] = {};
  std::size_t have = 0;
  while (have < cmd.size()) {
    const ssize_t n = ::recv(peer, got + have, sizeof got - have, 0);
    ASSERT_GT(n, 0);
    have += static_cast<std::size_t>(n);
  }
  EXPECT_EQ(std::string(got, have), cmd);

  ASSERT_EQ(::send(peer, "stale", 5, 0), 5);
  std::array<std::uint8_t, 64> buf{};
  // Wait until the stale bytes are here, then drain them.
  std::size_t seen = 0;
  {
    std::array<std::uint8_t, 1> one{};
    seen = t.read(one, std::chrono::milliseconds(2000));  // reads one byte of them
  }
  ASSERT_EQ(seen, 1u);
  t.drain_input();
  EXPECT_EQ(t.read(buf, std::chrono::milliseconds(20)), 0u);
  ASSERT_EQ(::send(peer, "OKAYA896\r", 9, 0), 9);
  std::size_t n = 0;
  while (n < 9) {
    const std::size_t k = t.read(std::span(buf).subspan(n), std::chrono::milliseconds(2000));
    ASSERT_GT(k, 0u);
    n += k;
  }
  EXPECT_EQ(std::string(buf.begin(), buf.begin() + 9), "OKAYA896\r");
  ::close(peer);
}

TEST(TcpTransport, PeerClosingIsPortLostNamingTheAddress) {
  Listener l;
  TcpTransport t(loopback(l.port));
  ::close(l.accept_one());
  std::array<std::uint8_t, 16> buf{};
  try {
    for (int i = 0; i < 100; ++i) t.read(buf, std::chrono::milliseconds(50));
    FAIL() << "no PortLost";
  } catch (const PortLost& e) {
    EXPECT_NE(std::string(e.what()).find("tcp:127.0.0.1:" + std::to_string(l.port)), std::string::npos) << e.what();
  }
}

TEST(TcpTransport, RefusedConnectionIsPortErrorSayingWhatToCheck) {
  int port = 0;
  { Listener l; port = l.port; }  // closed again: nothing listens there now
  try {
    TcpTransport t(loopback(port));
    FAIL() << "connected to a closed port";
  } catch (const PortError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("cannot connect"), std::string::npos) << what;
    EXPECT_NE(what.find(std::to_string(port)), std::string::npos) << what;
    EXPECT_NE(what.find("8765"), std::string::npos) << what;
  }
}

TEST(TcpTransport, AddressesParse) {
  auto a = parse_tcp_address("tcp:192.168.1.50:9000");
  ASSERT_TRUE(a);
  EXPECT_EQ(a->host, "192.168.1.50");
  EXPECT_EQ(a->port, 9000);
  a = parse_tcp_address("tcp:P9-B0103.local");
  ASSERT_TRUE(a);
  EXPECT_EQ(a->host, "P9-B0103.local");
  EXPECT_EQ(a->port, kNdiTcpPort);
  a = parse_tcp_address("tcp:[fe80::1]:8765");
  ASSERT_TRUE(a);
  EXPECT_EQ(a->host, "fe80::1");
  a = parse_tcp_address("tcp:fe80::1");
  ASSERT_TRUE(a);
  EXPECT_EQ(a->host, "fe80::1");
  EXPECT_FALSE(parse_tcp_address("/dev/ttyUSB0"));
  EXPECT_FALSE(parse_tcp_address("tcp:"));
  EXPECT_FALSE(parse_tcp_address("tcp:host:"));
  EXPECT_FALSE(parse_tcp_address("tcp:host:99999"));
  EXPECT_FALSE(parse_tcp_address("tcp:host:12a"));
}

}  // namespace
}  // namespace arnav::ndi
