// model.cpu_partition: which CPUs the model and the rendering side get, that the threads
// are really pinned, what the summary reports, and the errors (file:line) where the
// process cannot be partitioned.
#include <gtest/gtest.h>

#include <sched.h>

#include <sstream>
#include <thread>

#include "host/app/cpu_partition.hpp"
#include "host/app/navigation_session.hpp"
#include "host/app/test/session_test_util.hpp"
#include "host/scene/scene.hpp"
#include "protocol/clock.hpp"

namespace arnav::host {
namespace {

using namespace arnav::host::test;

// Runs f on a thread restricted to `cpus` (the plan reads the calling thread's mask).
template <typename F>
void on_cpus(const std::vector<int>& cpus, F f) {
  std::thread t([&] {
    ASSERT_EQ(pin_current_thread(cpus), "");
    f();
  });
  t.join();
}

TEST(CpuPartition, Plan) {
  const std::vector<int> all = current_thread_cpus();
  ASSERT_FALSE(all.empty());
  EXPECT_FALSE(plan_cpu_partition("off", true, true, 0.0).active);
  EXPECT_FALSE(plan_cpu_partition("auto", false, true, 0.0).active);  // no overlay: nothing to separate
  EXPECT_FALSE(plan_cpu_partition("auto", true, false, 0.0).active);
  EXPECT_THROW(plan_cpu_partition("on", false, true), std::invalid_argument);
  EXPECT_GE(load_average_1min(), 0.0);
  on_cpus({all.front()}, [] {
    EXPECT_FALSE(plan_cpu_partition("auto", true, true, 0.0).active);
    try {
      plan_cpu_partition("on", true, true);
      ADD_FAILURE() << "on with one CPU accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("at least 2 CPUs"), std::string::npos) << e.what();
    }
  });
  if (all.size() < 2) GTEST_SKIP() << "this machine gives the process one CPU: the two-CPU plan cannot be checked";
  const double n = static_cast<double>(all.size());
  // auto: on while the machine is quieter than its CPU count, off when it is busy or the load is unknown.
  EXPECT_FALSE(plan_cpu_partition("auto", true, true, n).active);
  EXPECT_NE(plan_cpu_partition("auto", true, true, n + 3).reason.find("busy with other work"), std::string::npos);
  EXPECT_FALSE(plan_cpu_partition("auto", true, true, -1.0).active);
  EXPECT_TRUE(plan_cpu_partition("on", true, true, n + 3).active);  // on: whatever the load
  const CpuPlan p = plan_cpu_partition("auto", true, true, n - 0.5);
  EXPECT_TRUE(p.active);
  EXPECT_NE(p.reason.find("on (auto"), std::string::npos);
  EXPECT_EQ(p.model_cpus, std::vector<int>{all.back()});
  EXPECT_EQ(p.render_cpus, std::vector<int>(all.begin(), all.end() - 1));
  on_cpus({all[0], all[1]}, [&] {
    const CpuPlan two = plan_cpu_partition("on", true, true);
    EXPECT_EQ(two.model_cpus, std::vector<int>{all[1]});
    EXPECT_EQ(two.render_cpus, std::vector<int>{all[0]});
    EXPECT_EQ(current_thread_cpus(), (std::vector<int>{all[0], all[1]}));
  });
}

TEST(CpuPartition, SessionPinsItsThreadsAndSaysSo) {
  const std::vector<int> all = current_thread_cpus();
  if (all.size() < 2) GTEST_SKIP() << "one CPU: nothing to partition";
  const Scene scene = load_scene(data_dir() + "/liver/liver_coarse.scene.yaml");
  SessionFolder f("cpu_partition");
  SessionOptions o;
  o.threaded = true;
  SessionConfig config = load_session(f.session());
  config.model.cpu_partition = "on";  // auto depends on the machine's load
  NavigationSession s(config, std::make_unique<Scene>(scene), o);
  s.start();
  for (int k = 0; k < 3; ++k) {
    const std::int64_t t = monotonic_us();
    s.on_pose(pose_msg("liver_marker", "Cam", test_X_CamRef(k), k, t), t);
    s.submit_frame(frame_msg(k, t), t);
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  s.stop();
  const nlohmann::json j = s.summary_json(1.0);
  ASSERT_TRUE(j.contains("cpu_partition"));
  const auto& cp = j["cpu_partition"];
  EXPECT_TRUE(cp["active"].get<bool>());
  EXPECT_EQ(cp["model_cpus"].get<std::vector<int>>(), std::vector<int>{all.back()});
  EXPECT_EQ(cp["render_cpus"].get<std::vector<int>>(), std::vector<int>(all.begin(), all.end() - 1));
  EXPECT_FALSE(cp.contains("render_pin_error"));
  EXPECT_FALSE(cp.contains("model_pin_error"));
  ASSERT_FALSE(cp["lp_num_threads"].is_null());  // set by the session (or kept from the environment)
  EXPECT_GE(j["frames_displayed"].get<int>(), 1);
  // Off: nothing applied.
  SessionFolder g("cpu_partition_off");
  const std::string off_text = "arnav_session_version: 1\nmodel: {cpu_partition: off}\n";
  EXPECT_EQ(load_session(g.write("off.yaml", off_text)).model.cpu_partition, "off");
  SessionConfig off_config = load_session(f.session());
  off_config.model.cpu_partition = "off";
  NavigationSession off(off_config, std::make_unique<Scene>(scene), o);
  off.start();
  off.stop();
  EXPECT_FALSE(off.summary_json(1.0)["cpu_partition"]["active"].get<bool>());
  // Replay (one thread) never partitions.
  SessionOptions replay;
  replay.threaded = false;
  NavigationSession r(load_session(f.session()), std::make_unique<Scene>(scene), replay);
  EXPECT_FALSE(r.summary_json(1.0)["cpu_partition"]["active"].get<bool>());
}

TEST(CpuPartition, OnWithOneCpuIsASessionError) {
  const std::vector<int> all = current_thread_cpus();
  const Scene scene = load_scene(data_dir() + "/liver/liver_coarse.scene.yaml");
  SessionFolder f("cpu_partition_one");
  const std::string path = f.session("");
  // The session file with cpu_partition: on (line 12 holds the model section).
  std::string text;
  {
    std::ifstream in(path);
    std::stringstream read;
    read << in.rdbuf();
    text = read.str();
  }
  const std::string from = "model: {rate_hz: 60, gravity: false}";
  text.replace(text.find(from), from.size(), "model: {rate_hz: 60, gravity: false, cpu_partition: on}");
  const SessionConfig c = load_session(f.write("on.yaml", text));
  on_cpus({all.front()}, [&] {
    SessionOptions o;
    o.threaded = true;
    try {
      NavigationSession s(c, std::make_unique<Scene>(scene), o);
      ADD_FAILURE() << "cpu_partition: on accepted with one CPU";
    } catch (const SessionError& e) {
      EXPECT_NE(std::string(e.what()).find("on.yaml:12: key 'model.cpu_partition': cpu_partition: on needs at least 2 CPUs"), std::string::npos)
          << e.what();
    }
  });
}

}  // namespace
}  // namespace arnav::host
