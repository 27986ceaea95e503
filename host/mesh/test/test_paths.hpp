#pragma once
// Paths of the source tree, the bundled data (data/) and a scratch folder for scene tests
// (set by arnav_add_test through the environment).
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>

namespace arnav::host::test {

inline std::string env_or(const char* name, const char* fallback) {
  const char* v = std::getenv(name);
  return v ? v : fallback;
}
inline std::string source_dir() { return env_or("ARNAV_SOURCE_DIR", "."); }
inline std::string data_meshes() { return env_or("ARNAV_DATA_DIR", "data") + "/meshes/"; }

// A fresh scratch folder per test binary.
inline std::string scratch(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / ("arnav_scene_test_" + std::to_string(::getpid())) / name;
  std::filesystem::create_directories(dir);
  return dir.string();
}

inline std::string write_file(const std::string& dir, const std::string& name, const std::string& content) {
  const std::string path = dir + "/" + name;
  std::ofstream(path, std::ios::binary) << content;
  return path;
}

}  // namespace arnav::host::test
