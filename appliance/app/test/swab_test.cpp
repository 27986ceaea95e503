// Pointer swab: the `swab:` configuration (errors with file:line) and the sampler that
// publishes the tool tip as arnav.point_cloud_t while the input is held (LCM memq://,
// in process).
#include <gtest/gtest.h>

#include <lcm/lcm-cpp.hpp>

#include <string>
#include <vector>

#include "appliance/app/config.hpp"
#include "appliance/app/swab.hpp"

using namespace arnav;
using namespace arnav::app;

namespace {

const std::vector<std::string> kTools = {"pointer", "patient"};
const std::vector<std::string> kInputs = {"pedal_swab", "pedal_cut"};

std::string config_error(const std::string& text) {
  try {
    parse_swab_config(text, "appliance.yaml", kTools, kInputs);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

struct Received {
  std::vector<point_cloud_t> messages;
  void on(const lcm::ReceiveBuffer*, const std::string&, const point_cloud_t* m) { messages.push_back(*m); }
};

Eigen::Isometry3d at(double x, double y, double z) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.translation() = Eigen::Vector3d(x, y, z);
  return X;
}

}  // namespace

TEST(SwabConfig, ParsesAndDefaults) {
  EXPECT_FALSE(parse_swab_config("port: sim\n", "a.yaml", kTools, kInputs).has_value());
  const auto c = parse_swab_config("port: sim\nswab:\n  tool: pointer\n  tip_mm: [0, 0, -160]\n  input: pedal_swab\n", "a.yaml", kTools, kInputs);
  ASSERT_TRUE(c.has_value());
  EXPECT_EQ(c->tool, "pointer");
  EXPECT_EQ(c->tip_Tool_mm, Eigen::Vector3d(0, 0, -160));
  EXPECT_EQ(c->input, "pedal_swab");
  EXPECT_FALSE(c->continuous);
  EXPECT_EQ(c->channel(), "ARNAV_CLOUD_pointer");
  EXPECT_EQ(c->points_per_message, 20);
  const auto k = parse_swab_config("swab:\n  tool: pointer\n  tip_mm: [1, 2, 3]\n  continuous: true\n  source: stylus\n  min_spacing_mm: 0.5\n",
                                   "a.yaml", kTools, kInputs);
  ASSERT_TRUE(k.has_value());
  EXPECT_TRUE(k->continuous);
  EXPECT_EQ(k->channel(), "ARNAV_CLOUD_stylus");
}

TEST(SwabConfig, ErrorsNameFileLineAndKey) {
  EXPECT_EQ(config_error("port: sim\nswab:\n  tool: probe\n  tip_mm: [0, 0, 1]\n  input: pedal_swab\n"),
            "appliance.yaml:3: key 'swab.tool': 'probe' is not an NDI tool under tools: (pointer, patient)");
  EXPECT_EQ(config_error("swab:\n  tool: pointer\n  tip_mm: [0, 0, 1]\n  input: pedal_x\n"),
            "appliance.yaml:4: key 'swab.input': 'pedal_x' is not a CAN input under can.inputs (pedal_swab, pedal_cut)");
  EXPECT_NE(config_error("swab:\n  tool: pointer\n  tip_mm: [0, 0]\n  input: pedal_swab\n").find("appliance.yaml:3: key 'swab.tip_mm'"), std::string::npos);
  EXPECT_NE(config_error("swab:\n  tool: pointer\n  tip_mm: [0, 0, .nan]\n  input: pedal_swab\n").find("key 'swab.tip_mm'"), std::string::npos);
  EXPECT_NE(config_error("swab:\n  tool: pointer\n  tip_mm: [0, 0, 1]\n").find("key 'swab.input': missing"), std::string::npos);
  EXPECT_NE(config_error("swab:\n  tool: pointer\n  tip_mm: [0, 0, 1]\n  input: pedal_swab\n  continuous: true\n").find("not both"), std::string::npos);
  EXPECT_NE(config_error("swab:\n  tool: pointer\n  tip_mm: [0, 0, 1]\n  input: pedal_swab\n  rate: 3\n").find("appliance.yaml:5: key 'swab.rate': unknown key"),
            std::string::npos);
  EXPECT_NE(config_error("swab:\n  tool: pointer\n  tip_mm: [0, 0, 1]\n  input: pedal_swab\n  points_per_message: 0\n").find("swab.points_per_message"),
            std::string::npos);
  EXPECT_NE(config_error("swab:\n  tool: pointer\n  tip_mm: [0, 0, 1]\n  input: pedal_swab\n  source: a.b\n").find("swab.source"), std::string::npos);
  // no CAN section: the input cannot exist
  try {
    parse_swab_config("swab:\n  tool: pointer\n  tip_mm: [0, 0, 1]\n  input: pedal_swab\n", "b.yaml", kTools, {});
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("no can: section"), std::string::npos) << e.what();
  }
  // and the appliance configuration accepts the section
  try {
    parse_config("port: sim\nswab: {}\n", "c.yaml", ".");
  } catch (const ConfigError& e) {
    EXPECT_EQ(std::string(e.what()).find("unknown key"), std::string::npos) << e.what();  // (it fails on the missing tools)
  }
}

TEST(SwabSampler, PublishesTheTipWhileTheInputIsHeld) {
  seal::SealedLcm lcm("memq://", seal::BusSecurity::off());
  ASSERT_TRUE(lcm.good());
  Received rx;
  lcm.subscribe("ARNAV_CLOUD_pointer", &Received::on, &rx);
  SwabConfig c;
  c.tool = "pointer";
  c.tip_Tool_mm = Eigen::Vector3d(0, 0, -100);
  c.input = "pedal_swab";
  c.points_per_message = 3;
  c.min_spacing_mm = 1.0;
  SwabSampler s(lcm, c);
  auto drain = [&] {
    while (lcm.handleTimeout(0) > 0) {
    }
  };
  s.on_frame(at(0, 0, 0), "Ref", 1);  // not held: nothing
  s.set_input("pedal_cut", true);     // another input: nothing
  s.on_frame(at(1, 0, 0), "Ref", 2);
  drain();
  EXPECT_TRUE(rx.messages.empty());
  s.set_input("pedal_swab", true);
  s.on_frame(at(0, 0, 0), "Ref", 10);
  s.on_frame(at(0.5, 0, 0), "Ref", 11);  // within 1 mm of the last sample: skipped
  s.on_frame(std::nullopt, "", 12);      // tool not seen: nothing
  s.on_frame(at(2, 0, 0), "Ref", 13);
  s.on_frame(at(4, 0, 0), "Ref", 14);    // third point: a message
  drain();
  ASSERT_EQ(rx.messages.size(), 1u);
  const point_cloud_t& m = rx.messages[0];
  EXPECT_EQ(m.frame_name, "Ref");
  EXPECT_EQ(m.source, "pointer");
  EXPECT_EQ(m.sequence, 0);
  EXPECT_EQ(m.capture_time_wall_us, 10);
  ASSERT_EQ(m.num_points, 3);
  EXPECT_EQ(m.num_normals, 0);
  EXPECT_EQ(m.num_ids, 0);
  EXPECT_DOUBLE_EQ(m.p_mm[0][2], -100.0);  // the tip, not the tool origin
  EXPECT_DOUBLE_EQ(m.p_mm[2][0], 4.0);
  s.on_frame(at(6, 0, 0), "Ref", 15);
  s.on_frame(at(8, 0, 0), "Ndi", 16);  // reference hidden: the pending Ref point goes out alone
  drain();
  ASSERT_EQ(rx.messages.size(), 2u);
  EXPECT_EQ(rx.messages[1].num_points, 1);
  EXPECT_EQ(rx.messages[1].frame_name, "Ref");
  s.set_input("pedal_swab", false);   // release: the pending Ndi point goes out with the next frame
  s.on_frame(at(10, 0, 0), "Ref", 17);
  drain();
  ASSERT_EQ(rx.messages.size(), 3u);
  EXPECT_EQ(rx.messages[2].frame_name, "Ndi");
  EXPECT_EQ(rx.messages[2].sequence, 2);
  EXPECT_EQ(s.points_published(), 5);
  s.on_frame(at(20, 0, 0), "Ref", 18);  // released: nothing more
  s.flush();
  drain();
  EXPECT_EQ(rx.messages.size(), 3u);
}

TEST(SwabSampler, ContinuousSamplesWithoutAnInput) {
  seal::SealedLcm lcm("memq://", seal::BusSecurity::off());
  Received rx;
  lcm.subscribe("ARNAV_CLOUD_pointer", &Received::on, &rx);
  SwabConfig c;
  c.tool = "pointer";
  c.continuous = true;
  c.points_per_message = 100;
  SwabSampler s(lcm, c);
  EXPECT_TRUE(s.active());
  for (int i = 0; i < 5; ++i) s.on_frame(at(2.0 * i, 0, 0), "Ndi", i);
  s.flush();
  while (lcm.handleTimeout(0) > 0) {
  }
  ASSERT_EQ(rx.messages.size(), 1u);
  EXPECT_EQ(rx.messages[0].num_points, 5);
}
