#include <gtest/gtest.h>

#include <cstring>

#include "appliance/ndi/crc16.hpp"
#include "appliance/ndi/reply.hpp"
#include "hil_tests/polaris_sim/device_model.hpp"
#include "hil_tests/polaris_sim/sim_device.hpp"

namespace arnav::hil {
namespace {

std::string rom_dir() { return std::string(std::getenv("ARNAV_DATA_DIR")) + "/ndi_roms/"; }

std::string cmd(const std::string& c) { return c + hex_field(ndi::crc16(c), 4) + "\r"; }

// Sends one command, expects exactly one reply and returns it as text.
std::string ask(SimDevice& d, const std::string& command, double now = 1.0, int* baud_after = nullptr) {
  const std::string line = cmd(command);
  auto replies = d.receive(std::span(reinterpret_cast<const std::uint8_t*>(line.data()), line.size()), now);
  EXPECT_EQ(replies.size(), 1u) << command;
  if (replies.empty()) return {};
  if (baud_after) *baud_after = replies[0].baud_after;
  return std::string(replies[0].bytes.begin(), replies[0].bytes.end());
}

std::string body(const std::string& reply) { return reply.size() >= 5 ? reply.substr(0, reply.size() - 5) : reply; }

std::string pvwr(const std::string& handle, unsigned addr, const std::vector<std::uint8_t>& rom) {
  std::string s = "PVWR:" + handle + hex_field(addr, 4);
  for (unsigned i = 0; i < 64; ++i) s += hex_field(addr + i < rom.size() ? rom[addr + i] : 0, 2);
  return s;
}

class ModelTest : public ::testing::Test {
 protected:
  ModelTest() : model(make_scenario()), device(model) { model.reset(0.0); }
  static Scenario make_scenario() {
    Scenario s;
    add_tool_spec(s, "pointer=" + rom_dir() + "8700340.rom");
    add_tool_spec(s, "reference=" + rom_dir() + "8700339.rom");
    return s;
  }
  // Loads a ROM into a new handle and returns the handle.
  std::string load(const std::string& rom_file) {
    const std::string h = body(ask(device, "PHRQ:*********1****"));
    EXPECT_EQ(h.size(), 2u);
    const auto rom = read_rom(rom_dir() + rom_file);
    for (unsigned addr = 0; addr < rom.size(); addr += 64) EXPECT_EQ(body(ask(device, pvwr(h, addr, rom))), "OKAY");
    return h;
  }
  PolarisModel model;
  ModelDevice device;
};

TEST_F(ModelTest, BringUpAndTracking) {
  EXPECT_EQ(body(ask(device, "PHSR:00")), "ERROR10");  // not initialised yet
  EXPECT_EQ(body(ask(device, "INIT:")), "OKAY");
  int baud = 0;
  EXPECT_EQ(body(ask(device, "COMM:50000", 1.0, &baud)), "OKAY");
  EXPECT_EQ(baud, 115200);
  EXPECT_NE(body(ask(device, "VER:0")).find("NDI S/N"), std::string::npos);
  const std::string p = load("8700340.rom");
  const std::string r = load("8700339.rom");
  const std::string stranger = load("8700248.rom");  // a ROM no scenario tool matches
  EXPECT_EQ(body(ask(device, "PHSR:02")), "03" + p + "000" + r + "000" + stranger + "000");
  for (const auto& h : {p, r, stranger}) EXPECT_EQ(body(ask(device, "PINIT:" + h)), "OKAY");
  EXPECT_EQ(body(ask(device, "PHINF:" + p + "0001")), "02000000NDI         00000000000" "11");
  EXPECT_EQ(body(ask(device, "PHINF:" + stranger + "0001")), "00000000            00000000000" "10");
  for (const auto& h : {p, r, stranger}) EXPECT_EQ(body(ask(device, "PENA:" + h + "D")), "OKAY");
  EXPECT_EQ(body(ask(device, "BX:0001")), "ERROR0C");  // not tracking yet
  EXPECT_EQ(body(ask(device, "TSTART:")), "OKAY");
  EXPECT_EQ(body(ask(device, "PHRQ:*********1****")), "ERROR0C");  // set-up is over

  std::vector<TruthRow> truth;
  model.on_truth = [&](const TruthRow& t) { truth.push_back(t); };
  const double now = 2.5;
  const std::string tx = body(ask(device, "TX:0001", now));
  const std::uint32_t frame = model.frame_at(now);
  EXPECT_EQ(frame, 1000u + 150u);  // 60 Hz since the reset at t=0
  ASSERT_EQ(truth.size(), 3u);
  EXPECT_EQ(truth[0].tool, "pointer");
  EXPECT_TRUE(truth[0].valid);
  EXPECT_EQ(truth[2].tool, "");
  EXPECT_FALSE(truth[2].valid);
  // The pose in the reply is the truth of that frame, to the TX resolution.
  const Eigen::Isometry3d X = model.scenario().tools[0].motion.X_NdiTool(frame / 60.0);
  EXPECT_TRUE(X.isApprox(truth[0].X_NdiTool));
  Eigen::Quaterniond q(X.rotation());
  if (q.w() < 0) q.coeffs() *= -1;
  ndi::HandleRecord rec;
  rec.q_NdiTool_wxyz = {q.w(), q.x(), q.y(), q.z()};
  rec.p_NdiTool_mm = {X.translation().x(), X.translation().y(), X.translation().z()};
  rec.rms_error_mm = model.scenario().tools[0].rms_error_mm;
  const std::string expect = "03" + p + ndi::format_transform(rec);
  EXPECT_EQ(tx.substr(0, expect.size()), expect);
  EXPECT_NE(tx.find(stranger + "MISSING00000030" + hex_field(frame, 8)), std::string::npos);

  EXPECT_EQ(body(ask(device, "TSTOP:")), "OKAY");
}

TEST_F(ModelTest, CommandErrors) {
  EXPECT_EQ(body(ask(device, "INIT:")), "OKAY");
  // Wrong CRC on a command.
  const std::string bad = "INIT:0000\r";
  auto r = device.receive(std::span(reinterpret_cast<const std::uint8_t*>(bad.data()), bad.size()), 1.0);
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(body(std::string(r[0].bytes.begin(), r[0].bytes.end())), "ERROR04");
  EXPECT_EQ(body(ask(device, "FOO:")), "ERROR01");
  EXPECT_EQ(body(ask(device, "COMM:90000")), "ERROR06");
  EXPECT_EQ(body(ask(device, "PINIT:01")), "ERROR08");
  const std::string h = body(ask(device, "PHRQ:*********1****"));
  EXPECT_EQ(body(ask(device, "PINIT:" + h)), "ERROR0D");  // no ROM loaded
  std::vector<std::uint8_t> not_ndi(64, 0x55);
  EXPECT_EQ(body(ask(device, pvwr(h, 0, not_ndi))), "OKAY");
  EXPECT_EQ(body(ask(device, "PINIT:" + h)), "ERROR41");
  EXPECT_EQ(body(ask(device, "PENA:" + h + "D")), "ERROR0E");
  EXPECT_EQ(body(ask(device, pvwr(h, 0x3F0, not_ndi))), "ERROR23");  // not 64-aligned
  // Space form without CRC is accepted.
  const std::string space = "BEEP 2\r";
  r = device.receive(std::span(reinterpret_cast<const std::uint8_t*>(space.data()), space.size()), 1.0);
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(body(std::string(r[0].bytes.begin(), r[0].bytes.end())), "1");
}

TEST_F(ModelTest, InjectedErrorsAndLostCommandsLeaveStateAlone) {
  EXPECT_EQ(body(ask(device, "INIT:")), "OKAY");
  ASSERT_TRUE(device.force_errors(0x0C, 1));
  EXPECT_EQ(body(ask(device, "TSTART:")), "ERROR0C");
  EXPECT_FALSE(model.tracking());
  ASSERT_TRUE(device.swallow_commands(1));
  const std::string line = cmd("TSTART:");
  EXPECT_TRUE(device.receive(std::span(reinterpret_cast<const std::uint8_t*>(line.data()), line.size()), 1.0).empty());
  EXPECT_FALSE(model.tracking());
  EXPECT_EQ(body(ask(device, "TSTART:")), "OKAY");
  EXPECT_TRUE(model.tracking());
}

TEST_F(ModelTest, MissingAndOutOfVolumeTools) {
  EXPECT_EQ(body(ask(device, "INIT:")), "OKAY");
  const std::string p = load("8700340.rom");
  EXPECT_EQ(body(ask(device, "PINIT:" + p)), "OKAY");
  EXPECT_EQ(body(ask(device, "PENA:" + p + "D")), "OKAY");
  EXPECT_EQ(body(ask(device, "TSTART:")), "OKAY");
  EXPECT_FALSE(device.hide_tool("nobody", 5.0, false));
  ASSERT_TRUE(device.hide_tool("pointer", 3.0, true));
  EXPECT_NE(ask(device, "TX:0001", 2.0).find("MISSING00000071"), std::string::npos);  // outside: reported missing
  EXPECT_EQ(ask(device, "TX:0801", 2.0).find("MISSING"), std::string::npos);          // unless asked for
  EXPECT_EQ(ask(device, "TX:0001", 3.5).find("MISSING"), std::string::npos);          // back inside
  ASSERT_TRUE(device.hide_tool("pointer", 5.0, false));
  EXPECT_NE(ask(device, "TX:0801", 4.0).find("MISSING00000031"), std::string::npos);
}

TEST(Model, ToolsWithoutRomTakeTheRemainingHandles) {
  Scenario s;
  add_tool_spec(s, "a=" + rom_dir() + "8700340.rom");
  s.tools.push_back(SimTool{});
  s.tools.back().name = "b";  // no ROM: takes the next unclaimed handle
  PolarisModel model(s);
  ModelDevice device(model);
  model.reset(0.0);
  EXPECT_EQ(body(ask(device, "INIT:")), "OKAY");
  const auto rom = read_rom(rom_dir() + "8700340.rom");
  std::vector<std::string> handles;
  for (int k = 0; k < 3; ++k) {  // the same ROM three times
    handles.push_back(body(ask(device, "PHRQ:*********1****")));
    for (unsigned addr = 0; addr < rom.size(); addr += 64) EXPECT_EQ(body(ask(device, pvwr(handles.back(), addr, rom))), "OKAY");
    EXPECT_EQ(body(ask(device, "PINIT:" + handles.back())), "OKAY");
  }
  EXPECT_EQ(body(ask(device, "PINIT:" + handles[0])), "OKAY");  // re-initialising keeps its tool
  std::vector<int> tools;
  for (const auto& [h, p] : model.ports()) tools.push_back(p.tool_index);
  EXPECT_EQ(tools, (std::vector<int>{0, 1, -1}));
}

TEST_F(ModelTest, ResetForgetsEverything) {
  EXPECT_EQ(body(ask(device, "INIT:")), "OKAY");
  load("8700340.rom");
  model.set_baud(115200);
  const Bytes msg = model.reset(10.0);
  EXPECT_EQ(std::string(msg.begin(), msg.end()), "RESETBE6F\r");
  EXPECT_EQ(model.baud(), 9600);
  EXPECT_TRUE(model.ports().empty());
  EXPECT_EQ(model.frame_at(10.0), 1000u);
  EXPECT_EQ(body(ask(device, "PHSR:00", 10.0)), "ERROR10");
}

// The realistic measurement model: the reply carries the pose fitted to noisy markers and
// the fit's RMS error, not the truth; the truth row keeps both.
TEST(Model, RealisticSensorsReportTheFittedPose) {
  Scenario s;
  add_tool_spec(s, "pointer=" + rom_dir() + "8700340.rom");
  s.measurement = MeasurementModel::realistic(21);
  s.measurement.dropout_rate = 0.0;
  PolarisModel model(s);
  ModelDevice device(model);
  model.reset(0.0);
  EXPECT_EQ(body(ask(device, "INIT:")), "OKAY");
  const std::string h = body(ask(device, "PHRQ:*********1****"));
  const auto rom = read_rom(rom_dir() + "8700340.rom");
  for (unsigned addr = 0; addr < rom.size(); addr += 64) EXPECT_EQ(body(ask(device, pvwr(h, addr, rom))), "OKAY");
  EXPECT_EQ(body(ask(device, "PINIT:" + h)), "OKAY");
  EXPECT_EQ(body(ask(device, "PENA:" + h + "D")), "OKAY");
  EXPECT_EQ(body(ask(device, "TSTART:")), "OKAY");
  std::vector<TruthRow> truth;
  model.on_truth = [&](const TruthRow& t) { truth.push_back(t); };
  for (int k = 0; k < 5; ++k) {
    truth.clear();
    const std::string tx = body(ask(device, "TX:0001", 2.0 + k * 0.1));
    ASSERT_EQ(truth.size(), 1u);
    const TruthRow& t = truth[0];
    ASSERT_TRUE(t.valid);
    const double off_mm = (t.X_NdiTool_reported.translation() - t.X_NdiTool.translation()).norm();
    EXPECT_GT(off_mm, 1e-4);  // noise is there
    EXPECT_LT(off_mm, 3.0);   // and of the configured size (0.25 mm RMS per marker)
    EXPECT_GT(t.rms_error_mm, 0.0);
    Eigen::Quaterniond q(t.X_NdiTool_reported.rotation());
    if (q.w() < 0) q.coeffs() *= -1;
    ndi::HandleRecord rec;
    rec.q_NdiTool_wxyz = {q.w(), q.x(), q.y(), q.z()};
    const Eigen::Vector3d p = t.X_NdiTool_reported.translation();
    rec.p_NdiTool_mm = {p.x(), p.y(), p.z()};
    rec.rms_error_mm = t.rms_error_mm;
    const std::string expect = "01" + h + ndi::format_transform(rec);
    EXPECT_EQ(tx.substr(0, expect.size()), expect);
  }
}

}  // namespace
}  // namespace arnav::hil
