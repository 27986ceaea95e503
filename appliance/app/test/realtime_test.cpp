#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <thread>

#include <sched.h>
#include <unistd.h>

#include "appliance/app/config.hpp"
#include "appliance/realtime/realtime.hpp"
#include "protocol/testing/error_of.hpp"

namespace arnav::app {
namespace {

TEST(Realtime, CpuLatencyRequestWritesABinaryInt32) {
  // The PM QoS device takes a raw 32-bit value; an ordinary file shows what was written.
  const auto path = std::filesystem::temp_directory_path() / ("arnav_pmqos_" + std::to_string(::getpid()));
  std::ofstream(path).close();
  {
    CpuLatencyRequest request(7, path.string());
    EXPECT_TRUE(request.held()) << request.error();
    EXPECT_TRUE(request.error().empty());
  }
  std::ifstream in(path, std::ios::binary);
  std::int32_t value = -1;
  in.read(reinterpret_cast<char*>(&value), sizeof value);
  EXPECT_EQ(in.gcount(), 4);
  EXPECT_EQ(value, 7);
  std::filesystem::remove(path);
}

TEST(Realtime, CpuLatencyRequestNamesTheDeviceWhenRefused) {
  CpuLatencyRequest request(0, "/nonexistent/cpu_dma_latency");
  EXPECT_FALSE(request.held());
  EXPECT_NE(request.error().find("/nonexistent/cpu_dma_latency"), std::string::npos) << request.error();
  EXPECT_NE(request.error().find("realtime.cpu_latency_us"), std::string::npos) << request.error();
}

TEST(Realtime, NegativeLatencyAsksNothing) {
  CpuLatencyRequest request(-1, "/nonexistent/cpu_dma_latency");
  EXPECT_FALSE(request.held());
  EXPECT_TRUE(request.error().empty());
}

TEST(Realtime, PriorityZeroLeavesSchedulingAlone) {
  std::thread([] {
    EXPECT_EQ(make_this_thread_realtime(0), "");
    EXPECT_EQ(sched_getscheduler(0), SCHED_OTHER);
  }).join();
}

TEST(Realtime, FifoOnTheCallingThreadOnlyOrAClearRefusal) {
  std::thread([] {
    const std::string error = make_this_thread_realtime(10);
    if (error.empty()) {
      EXPECT_EQ(sched_getscheduler(0) & ~SCHED_RESET_ON_FORK, SCHED_FIFO);
      // Reset-on-fork: threads and processes it starts run normally.
      int child_policy = -1;
      std::thread([&] { child_policy = sched_getscheduler(0); }).join();
      EXPECT_EQ(child_policy, SCHED_OTHER);
    } else {  // not root / no CAP_SYS_NICE: the message says what to do
      EXPECT_NE(error.find("realtime.priority"), std::string::npos) << error;
      EXPECT_EQ(sched_getscheduler(0), SCHED_OTHER);
    }
  }).join();
  EXPECT_EQ(sched_getscheduler(0), SCHED_OTHER) << "the test's own thread must stay normal";
  EXPECT_NE(make_this_thread_realtime(100).find("outside"), std::string::npos);
}

AppConfig parse(const std::string& text) {
  const char* data = std::getenv("ARNAV_DATA_DIR");
  if (!data) throw std::runtime_error("ARNAV_DATA_DIR is not set (run the test through ctest)");
  return parse_config(text, "cfg.yaml", std::filesystem::path(data) / "ndi_roms");
}

const std::string kBase = "port: sim\ntools:\n  - {name: pointer, rom: 8700340.rom}\n";

TEST(Realtime, ConfigDefaultsAndValues) {
  const AppConfig d = parse(kBase);
  EXPECT_EQ(d.realtime.cpu_latency_us, 0);
  EXPECT_EQ(d.realtime.priority, 50);
  const AppConfig c = parse(kBase + "realtime: {cpu_latency_us: -1, priority: 40}\n");
  EXPECT_EQ(c.realtime.cpu_latency_us, -1);
  EXPECT_EQ(c.realtime.priority, 40);
}

TEST(Realtime, ConfigErrorsNameKeyAndLine) {
  auto error_of = [](const std::string& text) { return arnav::testing::error_of<ConfigError>([&] { parse(text); }); };
  EXPECT_NE(error_of(kBase + "realtime: {priority: 120}\n").find("cfg.yaml:4: key 'realtime.priority'"), std::string::npos);
  EXPECT_NE(error_of(kBase + "realtime: {cpu_latency_us: -5}\n").find("key 'realtime.cpu_latency_us'"), std::string::npos);
  EXPECT_NE(error_of(kBase + "realtime:\n  nice: 3\n").find("cfg.yaml:5: key 'realtime.nice': unknown key"), std::string::npos);
  EXPECT_NE(error_of(kBase + "realtime: fast\n").find("key 'realtime'"), std::string::npos);
  EXPECT_NE(error_of("camera:\n  source: synthetic\nrealtime: {priority: 50}\n").find("cfg.yaml:3: key 'realtime': applies to the NDI"),
            std::string::npos);
}

}  // namespace
}  // namespace arnav::app
