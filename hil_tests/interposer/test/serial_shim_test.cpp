// The production serial path (unmodified libserialport) on the simulated Polaris, in a
// private mount + network namespace with the pty bind-mounted over /dev/ttyS0. Without
// the shim libserialport cannot open a pty; with it, modem lines and breaks work.
#include <gtest/gtest.h>

#include <filesystem>

#include "hil_tests/bench/child_process.hpp"
#include "hil_tests/bench/namespaces.hpp"
#include "hil_tests/bench/bench_required.hpp"

namespace arnav::hil {
namespace {

namespace fs = std::filesystem;

class SerialShim : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string why = enter_bench_namespaces();
    ARNAV_BENCH_OR_SKIP(why);
    if (!fs::exists("/sys/class/tty/ttyS0") || !fs::exists("/dev/ttyS0"))
      GTEST_SKIP() << "no /dev/ttyS0 with a sysfs entry on this machine: nothing to bind the pty over";
    dir = make_temp_dir("arnav-shim");
    sim = std::make_unique<ChildProcess>(
        std::vector<std::string>{ARNAV_POLARIS_SIM_EXE, "--pty-link", dir + "/polaris", "--bind-over", "/dev/ttyS0",
                                 "--break-socket", dir + "/break.sock"},
        std::vector<std::string>{}, dir + "/sim.log", true);
    const auto ready = sim->read_line(20.0);
    ASSERT_TRUE(ready && ready->rfind("READY ", 0) == 0) << sim->log_tail();
  }
  void TearDown() override {
    if (sim) {
      EXPECT_EQ(sim->stop(), 0) << sim->log_tail();
    }
    if (!dir.empty()) fs::remove_all(dir);
  }
  std::string dir;
  std::unique_ptr<ChildProcess> sim;
};

TEST_F(SerialShim, LibserialportNeedsTheShimOnAPty) {
  ChildProcess probe({ARNAV_SERIAL_PROBE_EXE, "/dev/ttyS0"}, {}, dir + "/probe.log");
  EXPECT_EQ(probe.wait(60.0).value_or(-1), 1) << probe.log_tail();
  EXPECT_NE(probe.log_tail().find("open: FAILED"), std::string::npos) << probe.log_tail();
}

TEST_F(SerialShim, OpenBaudSwitchAndBreakWork) {
  ChildProcess probe({ARNAV_SERIAL_PROBE_EXE, "/dev/ttyS0"},
                     {"LD_PRELOAD=" ARNAV_SERIAL_SHIM_LIB, "ARNAV_HIL_BREAK_SOCKET=" + dir + "/break.sock"}, dir + "/probe.log");
  EXPECT_EQ(probe.wait(60.0).value_or(-1), 0) << probe.log_tail() << "\n--- sim ---\n" << sim->log_tail();
  EXPECT_NE(probe.log_tail().find("RESET after break: ok"), std::string::npos);
}

}  // namespace
}  // namespace arnav::hil
