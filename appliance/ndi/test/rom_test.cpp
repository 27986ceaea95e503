#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>

#include <unistd.h>

#include "appliance/ndi/rom.hpp"

namespace arnav::ndi {
namespace {

std::filesystem::path rom_dir() {
  const char* data = std::getenv("ARNAV_DATA_DIR");
  if (!data) throw std::runtime_error("ARNAV_DATA_DIR is not set (run the test through ctest)");
  return std::filesystem::path(data) / "ndi_roms";
}

std::filesystem::path write_temp(const std::string& name, const std::string& content) {
  auto p = std::filesystem::temp_directory_path() / ("arnav_rom_test_" + std::to_string(::getpid()) + "_" + name);
  std::ofstream(p, std::ios::binary) << content;
  return p;
}

TEST(Rom, AllRealRomsLoad) {
  int n = 0;
  for (const auto& e : std::filesystem::directory_iterator(rom_dir())) {
    ToolRom rom = load_rom(e.path());
    EXPECT_EQ(rom.bytes.size(), 752u) << e.path();
    EXPECT_EQ(rom.chunk_count(), 16u);
    ++n;
  }
  EXPECT_EQ(n, 5);
}

void expect_refused(const std::filesystem::path& p, const std::string& needle) {
  try {
    load_rom(p);
    ADD_FAILURE() << "accepted " << p;
  } catch (const RomError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(p.string()), std::string::npos) << what;
    EXPECT_NE(what.find(needle), std::string::npos) << what;
  }
}

TEST(Rom, RefusesNonNdiFilesNamingThem) {
  auto text = write_temp("text.rom", "this is not a rom\n");
  expect_refused(text, "NDI\\0");
  auto empty = write_temp("empty.rom", "");
  expect_refused(empty, "empty");
  auto nearly = write_temp("nearly.rom", std::string("NDI!") + std::string(100, '\0'));
  expect_refused(nearly, "NDI\\0");
  expect_refused("/nonexistent/tool.rom", "not found");
  std::filesystem::remove(text);
  std::filesystem::remove(empty);
  std::filesystem::remove(nearly);
}

}  // namespace
}  // namespace arnav::ndi
