// The simulator executable on a real pseudo-terminal, driven by a plain termios client
// (no root needed): READY contract, baud switching and mismatch, bring-up, BX frames
// against the ground-truth file, faults from the control socket, cable pull, reset.
#include <fcntl.h>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include "appliance/ndi/crc16.hpp"
#include "hil_tests/bench/child_process.hpp"
#include "hil_tests/bench/namespaces.hpp"
#include "hil_tests/polaris_sim/reply_encoder.hpp"
#include "hil_tests/polaris_sim/scenario.hpp"

namespace arnav::hil {
namespace {

namespace fs = std::filesystem;
const std::string kSim = ARNAV_POLARIS_SIM_EXE;
std::string rom(const std::string& name) { return std::string(std::getenv("ARNAV_DATA_DIR")) + "/ndi_roms/" + name; }

speed_t speed_of(int baud) {
  switch (baud) {
    case 9600: return B9600;
    case 57600: return B57600;
    case 115200: return B115200;
    default: return B0;
  }
}

// A minimal host end: raw termios, commands with CRC, replies up to CR or one BX frame.
struct Host {
  int fd = -1;
  explicit Host(const std::string& path) {
    fd = ::open(path.c_str(), O_RDWR | O_NOCTTY | O_CLOEXEC);
    if (fd < 0) return;
    set_baud(9600);
  }
  ~Host() {
    if (fd >= 0) ::close(fd);
  }
  void set_baud(int baud) {
    termios t{};
    tcgetattr(fd, &t);
    cfmakeraw(&t);
    cfsetispeed(&t, speed_of(baud));
    cfsetospeed(&t, speed_of(baud));
    tcsetattr(fd, TCSANOW, &t);
  }
  void send(const std::string& command) {
    const std::string line = command + hex_field(ndi::crc16(command), 4) + "\r";
    ASSERT_EQ(::write(fd, line.data(), line.size()), static_cast<ssize_t>(line.size()));
  }
  // Reads until `done(bytes)` or timeout; returns what arrived.
  template <typename Done>
  std::string read_until(Done done, double timeout_s) {
    std::string got;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (!done(got)) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now()).count();
      if (left <= 0) break;
      pollfd p{fd, POLLIN, 0};
      if (::poll(&p, 1, static_cast<int>(left)) <= 0) continue;
      char c;
      const ssize_t n = ::read(fd, &c, 1);
      if (n <= 0) break;
      got.push_back(c);
    }
    return got;
  }
  std::string text(double timeout_s = 5.0) {
    return read_until([](const std::string& s) { return !s.empty() && s.back() == '\r'; }, timeout_s);
  }
  std::string ask(const std::string& command, double timeout_s = 5.0) {
    send(command);
    return text(timeout_s);
  }
  std::string bx(double timeout_s = 5.0) {
    return read_until([](const std::string& s) { return s.size() >= 6 && s.size() >= 8u + (static_cast<unsigned char>(s[2]) | (static_cast<unsigned char>(s[3]) << 8)); },
                      timeout_s);
  }
};

bool text_crc_ok(const std::string& r) {
  if (r.size() < 6 || r.back() != '\r') return false;
  const std::string b = r.substr(0, r.size() - 1);
  return hex_field(ndi::crc16(b.substr(0, b.size() - 4)), 4) == b.substr(b.size() - 4);
}
bool bx_crc_ok(const std::string& f) {
  if (f.size() < 8) return false;
  const auto* u = reinterpret_cast<const std::uint8_t*>(f.data());
  const std::size_t len = u[2] | (u[3] << 8);
  if (f.size() != len + 8) return false;
  return (u[4] | (u[5] << 8)) == ndi::crc16(std::span(u, 4)) && (u[6 + len] | (u[7 + len] << 8)) == ndi::crc16(std::span(u + 6, len));
}

std::string pvwr(const std::string& h, unsigned addr, const std::vector<std::uint8_t>& r) {
  std::string s = "PVWR:" + h + hex_field(addr, 4);
  for (unsigned i = 0; i < 64; ++i) s += hex_field(addr + i < r.size() ? r[addr + i] : 0, 2);
  return s;
}

class SimPty : public ::testing::Test {
 protected:
  void SetUp() override {
    dir = make_temp_dir("arnav-sim-pty");
    link = dir + "/polaris";
    control = dir + "/control.sock";
    truth = dir + "/truth.csv";
    sim = std::make_unique<ChildProcess>(
        std::vector<std::string>{kSim, "--pty-link", link, "--tool", "pointer=" + rom("8700340.rom"), "--rate", "100",
                                 "--control", control, "--truth", truth, "--reset-delay", "0.1"},
        std::vector<std::string>{}, dir + "/sim.log", true);
    const auto ready = sim->read_line(20.0);
    ASSERT_TRUE(ready.has_value()) << sim->log_tail();
    ASSERT_EQ(ready->rfind("READY /dev/pts/", 0), 0u) << *ready;
    EXPECT_EQ(fs::read_symlink(link).string(), ready->substr(6));
  }
  void TearDown() override {
    if (sim) {
      EXPECT_EQ(sim->stop(), 0) << sim->log_tail();
      EXPECT_FALSE(fs::exists(fs::symlink_status(link))) << "the pty link outlives the simulator";
    }
    if (HasFailure() && sim) std::cerr << "--- simulator log ---\n" << sim->log_tail() << "\n";
    fs::remove_all(dir);
  }
  void inject(const std::string& command) {
    ChildProcess c({kSim, "inject", "--control", control, command}, {}, dir + "/inject.log", true);
    EXPECT_EQ(c.read_line(10.0).value_or(""), "OK");
    EXPECT_EQ(c.wait(10.0).value_or(-1), 0);
  }
  // INIT, COMM to 115200, one tool loaded, enabled, tracking. Returns its handle.
  std::string bring_up(Host& host) {
    EXPECT_EQ(host.ask("INIT:"), "OKAYA896\r");
    EXPECT_EQ(host.ask("COMM:50000"), "OKAYA896\r");
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    host.set_baud(115200);
    const std::string h = host.ask("PHRQ:*********1****").substr(0, 2);
    const auto r = read_rom(rom("8700340.rom"));
    for (unsigned a = 0; a < r.size(); a += 64) EXPECT_EQ(host.ask(pvwr(h, a, r)), "OKAYA896\r");
    EXPECT_EQ(host.ask("PINIT:" + h), "OKAYA896\r");
    EXPECT_EQ(host.ask("PENA:" + h + "D"), "OKAYA896\r");
    EXPECT_EQ(host.ask("TSTART:"), "OKAYA896\r");
    return h;
  }
  std::string dir, link, control, truth;
  std::unique_ptr<ChildProcess> sim;
};

TEST_F(SimPty, BaudSwitchAndMismatch) {
  Host host(link);
  ASSERT_GE(host.fd, 0);
  EXPECT_EQ(host.ask("INIT:"), "OKAYA896\r");
  EXPECT_EQ(host.ask("COMM:50000"), "OKAYA896\r");  // answered at the old rate
  // Still at 9600 on our side: the device has moved on, so INIT goes unanswered.
  const std::string silent = host.ask("INIT:", 0.5);
  EXPECT_EQ(silent.find("OKAY"), std::string::npos);
  host.set_baud(115200);
  EXPECT_EQ(host.ask("INIT:"), "OKAYA896\r");
  inject("baud_mismatch 57600");
  EXPECT_EQ(host.ask("INIT:", 0.5).find("OKAY"), std::string::npos);
  host.set_baud(57600);  // a host probing the other rates finds it
  EXPECT_EQ(host.ask("INIT:"), "OKAYA896\r");
}

TEST_F(SimPty, TrackingFramesMatchGroundTruth) {
  Host host(link);
  ASSERT_GE(host.fd, 0);
  const std::string h = bring_up(host);
  std::map<std::uint32_t, std::array<float, 7>> seen;
  for (int i = 0; i < 50; ++i) {
    host.send("BX:0001");
    const std::string f = host.bx();
    ASSERT_TRUE(bx_crc_ok(f)) << "frame " << i;
    const auto* u = reinterpret_cast<const std::uint8_t*>(f.data());
    ASSERT_EQ(u[6], 1);
    ASSERT_EQ(u[7], std::stoul(h, nullptr, 16));
    ASSERT_EQ(u[8], 0x01);
    std::array<float, 7> v;
    std::memcpy(v.data(), u + 9, sizeof v);
    std::uint32_t frame;
    std::memcpy(&frame, u + 9 + 36, 4);
    seen[frame] = v;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  EXPECT_GT(seen.size(), 5u);  // the 100 Hz counter moved while we polled
  EXPECT_EQ(host.ask("TSTOP:"), "OKAYA896\r");
  ASSERT_EQ(sim->stop(), 0);
  std::ifstream in(truth);
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "frame,handle,tool,valid,port_status,qw,qx,qy,qz,x_mm,y_mm,z_mm,"
                  "reported_qw,reported_qx,reported_qy,reported_qz,reported_x_mm,reported_y_mm,reported_z_mm,rms_error_mm,dropout");
  std::size_t matched = 0;
  while (std::getline(in, line)) {
    std::stringstream ss(line);
    std::vector<std::string> c;
    for (std::string cell; std::getline(ss, cell, ',');) c.push_back(cell);
    ASSERT_EQ(c.size(), 21u);  // true pose, then the reported one (equal: no measurement block, ideal sensors)
    const auto it = seen.find(static_cast<std::uint32_t>(std::stoul(c[0])));
    if (it == seen.end()) continue;
    EXPECT_EQ(c[2], "pointer");
    for (int k = 0; k < 7; ++k) {
      EXPECT_EQ(it->second[k], static_cast<float>(std::stod(c[12 + k]))) << line;
      EXPECT_EQ(it->second[k], static_cast<float>(std::stod(c[5 + k]))) << line;
    }
    ++matched;
  }
  EXPECT_EQ(matched, seen.size());
}

TEST_F(SimPty, ReplyFaults) {
  Host host(link);
  ASSERT_GE(host.fd, 0);
  bring_up(host);
  inject("bad_crc");
  host.send("BX:0001");
  EXPECT_FALSE(bx_crc_ok(host.bx()));
  host.send("BX:0001");
  EXPECT_TRUE(bx_crc_ok(host.bx()));
  inject("error 0C");
  EXPECT_EQ(host.ask("BX:0001").substr(0, 7), "ERROR0C");
  inject("no_reply");
  EXPECT_EQ(host.ask("BX:0001", 0.5), "");
  inject("garble 2");
  host.send("TX:0001");
  EXPECT_FALSE(text_crc_ok(host.text(2.0)));
  inject("chunked 2");
  host.send("TX:0001");
  EXPECT_TRUE(text_crc_ok(host.text()));  // chunks reassemble into a good reply
  inject("slow 0.4");
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_TRUE(text_crc_ok(host.ask("TX:0001")));
  EXPECT_GE(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 0.35);
  // Unknown tool and bad commands are refused with a reason.
  ChildProcess c({kSim, "inject", "--control", control, "missing nobody 1"}, {}, dir + "/inject.log", true);
  EXPECT_NE(c.read_line(10.0).value_or("").find("no tool named 'nobody'"), std::string::npos);
  EXPECT_EQ(c.wait(10.0).value_or(-1), 1);
}

TEST_F(SimPty, CablePullAndReset) {
  {
    Host host(link);
    ASSERT_GE(host.fd, 0);
    bring_up(host);
    inject("cable_pull 1");
    EXPECT_FALSE(fs::exists(fs::symlink_status(link)));
    char c;
    pollfd p{host.fd, POLLIN, 0};
    ::poll(&p, 1, 1000);
    EXPECT_LE(::read(host.fd, &c, 1), 0);  // hang-up on the old port
  }
  const auto t0 = std::chrono::steady_clock::now();
  while (!fs::exists(link) && std::chrono::steady_clock::now() - t0 < std::chrono::seconds(10))
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  ASSERT_TRUE(fs::exists(link)) << "the port did not come back";
  Host host(link);
  ASSERT_GE(host.fd, 0);
  host.set_baud(115200);  // the unit kept its state while unplugged
  EXPECT_EQ(host.ask("INIT:"), "OKAYA896\r");
  host.set_baud(9600);
  inject("reset");
  EXPECT_EQ(host.text(), "RESETBE6F\r");
  EXPECT_EQ(host.ask("BX:0001").substr(0, 7), "ERROR10");  // forgot INIT and tracking
}

// Replay mode through the executable: the real IGSTK capture acted out on the pty.
TEST(SimReplay, ActsOutTheRealCaptureOnThePty) {
  const std::string dir = make_temp_dir("arnav-sim-replay");
  const std::string capture = std::string(std::getenv("ARNAV_DATA_DIR")) + "/ndi_captures/polaris_classic_stream.txt";
  ChildProcess sim({kSim, "--pty-link", dir + "/polaris", "--replay", capture, "--control", dir + "/control.sock"}, {}, dir + "/sim.log", true);
  ASSERT_TRUE(sim.read_line(20.0).value_or("").rfind("READY ", 0) == 0) << sim.log_tail();
  {
    Host host(dir + "/polaris");
    ASSERT_GE(host.fd, 0);
    EXPECT_EQ(host.ask("INIT:"), "OKAYA896\r");
    EXPECT_NE(host.ask("VER:0").find("Polaris Control Firmware"), std::string::npos);
    EXPECT_EQ(host.ask("COMM:50000"), "OKAYA896\r");  // as recorded; the replay switches too
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    host.set_baud(115200);
    EXPECT_EQ(host.ask("BX:0001").substr(0, 7), "ERROR01");  // never recorded
    ChildProcess c({kSim, "inject", "--control", dir + "/control.sock", "no_reply"}, {}, dir + "/inject.log", true);
    EXPECT_NE(c.read_line(10.0).value_or("").find("cannot model"), std::string::npos);
  }
  EXPECT_EQ(sim.stop(), 0) << sim.log_tail();
  EXPECT_NE(sim.log_tail().find("is not in"), std::string::npos);
  fs::remove_all(dir);
}

// --wire-timing paces replies at the device's baud rate: never faster than 10 bits a byte.
TEST(SimWireTiming, RepliesTakeTheirWireTime) {
  const std::string dir = make_temp_dir("arnav-sim-wire");
  ChildProcess sim({kSim, "--pty-link", dir + "/polaris", "--wire-timing"}, {}, dir + "/sim.log", true);
  ASSERT_TRUE(sim.read_line(20.0).value_or("").rfind("READY ", 0) == 0) << sim.log_tail();
  {
    Host host(dir + "/polaris");
    ASSERT_GE(host.fd, 0);
    const auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < 5; ++i) EXPECT_EQ(host.ask("INIT:"), "OKAYA896\r");
    // 5 replies of 9 bytes at 9600 baud: at least 5 * 9 * 10 / 9600 s = 46.9 ms (the
    // first one may go out at once).
    EXPECT_GE(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 4 * 9 * 10 / 9600.0);
  }
  EXPECT_EQ(sim.stop(), 0);
  fs::remove_all(dir);
}

TEST(SimCli, UsageErrorsExitTwo) {
  const std::string dir = make_temp_dir("arnav-sim-cli");
  ChildProcess none({kSim}, {}, dir + "/a.log");
  EXPECT_EQ(none.wait(20.0).value_or(-1), 2);
  ChildProcess bad_tool({kSim, "--pty-link", dir + "/p", "--tool", "pointer=/nonexistent.rom"}, {}, dir + "/b.log");
  EXPECT_EQ(bad_tool.wait(20.0).value_or(-1), 2);
  EXPECT_NE(bad_tool.log_tail().find("/nonexistent.rom"), std::string::npos);
  ChildProcess bad_fault({kSim, "--pty-link", dir + "/p", "--fault", "3:missing ghost 1"}, {}, dir + "/c.log");
  EXPECT_EQ(bad_fault.wait(20.0).value_or(-1), 2);
  ChildProcess help({kSim, "--help"}, {}, dir + "/d.log");
  EXPECT_EQ(help.wait(20.0).value_or(-1), 0);
  EXPECT_NE(help.log_tail().find("cable_pull"), std::string::npos);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace arnav::hil
