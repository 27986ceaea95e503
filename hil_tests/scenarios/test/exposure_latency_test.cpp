// Exposure to display on the bench (latency_session.sh, short): the synthetic camera at
// 30 Hz for 3 s through the real arnav-appliance, LCM in a private network namespace and
// the real arnav-host. Checked, for every frame, not for speed (the machine may be busy):
// the camera wrote exactly one timing row per frame of its range (delivered, or dropped
// with its cause: never a silent skip); every shown frame's instants are in order
// (exposure <= readout end <= delivered <= published <= received <= decoded <= ready <=
// shown) and its exposure is the one the camera stamped; the modelled readout is one frame
// period; the frames not shown add up to the dropped count by cause, the host's counts
// included, and none is counted twice (lost after delivery >= 0).
#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "hil_tests/bench/bench_required.hpp"

namespace arnav::hil {
namespace {

std::string env(const char* name, const char* fallback) {
  const char* v = std::getenv(name);
  return v ? v : fallback;
}

TEST(ExposureLatency, StampsInOrderForEveryFrameAndDropsCountedByCause) {
  ARNAV_BENCH_OR_SKIP(::geteuid() != 0 ? "needs root for a private network namespace (unshare --net)" : "");
  const std::filesystem::path out = std::filesystem::temp_directory_path() / ("arnav-exposure-latency-" + std::to_string(::getpid()));
  std::filesystem::remove_all(out);
  const std::string script = env("ARNAV_SOURCE_DIR", ".") + std::string("/hil_tests/scenarios/latency_session.sh");
  const std::string cmd = script + " " + env("ARNAV_BINARY_DIR", ".") + " " + out.string() + " 3 30 >" + out.string() + ".log 2>&1";
  const int rc = std::system(cmd.c_str());
  std::ifstream log_in(out.string() + ".log");
  std::stringstream log;
  log << log_in.rdbuf();
  ASSERT_EQ(rc, 0) << log.str();
  EXPECT_NE(log.str().find("exposure-to-display: p50 "), std::string::npos) << log.str();

  std::ifstream j_in(out / "latency.json");
  const nlohmann::json j = nlohmann::json::parse(j_in);
  const auto& c = j["checks"];
  EXPECT_EQ(c["timing_rows_missing"].get<int>(), 0) << j.dump(2);
  EXPECT_EQ(c["timing_rows_duplicated"].get<int>(), 0);
  EXPECT_EQ(c["shown_not_delivered"].get<int>(), 0);
  EXPECT_EQ(c["exposure_mismatch"].get<int>(), 0);
  EXPECT_EQ(c["stamps_out_of_order"].get<int>(), 0) << c.value("first_out_of_order", "");

  const auto& f = j["frames"];
  const int exposed = f["exposed"].get<int>(), shown = f["shown"].get<int>();
  EXPECT_GE(exposed, 80);  // 90 frames; the first may fall before the camera opened
  EXPECT_GT(shown, 0);
  EXPECT_EQ(j["exposure_to_display_ms"]["n"].get<int>(), shown);
  const auto& d = j["dropped"];
  EXPECT_EQ(d["total"].get<int>(), exposed - shown);
  EXPECT_EQ(d["total"].get<int>(), d["camera_render_late"].get<int>() + d["camera_reader_late"].get<int>() + d["host_dropped"].get<int>() +
                                       d["host_undecodable"].get<int>() + d["lost_after_delivery"].get<int>());
  EXPECT_GE(d["lost_after_delivery"].get<int>(), 0) << "frames counted as dropped twice: " << j.dump(2);
  // The sensor's readout is modelled as one frame period.
  EXPECT_NEAR(j["stages_ms"]["readout (modelled)"]["p50"].get<double>(), 1000.0 / 30.0, 0.01);

  // The host's own summary agrees: every frame it displayed is in overlay.csv and the latency.
  std::ifstream h_in(out / "host.json");
  const nlohmann::json h = nlohmann::json::parse(h_in);
  const auto& nav = h["navigation"];
  EXPECT_EQ(nav["frames_displayed"].get<int>(), shown);
  EXPECT_EQ(nav["latency"]["stamps_out_of_order"].get<int>(), 0);
  EXPECT_EQ(nav["latency"]["misses"]["dropped_by_host"].get<int>(), d["host_dropped"].get<int>());
  std::filesystem::remove_all(out);
  std::filesystem::remove(out.string() + ".log");
}

}  // namespace
}  // namespace arnav::hil
