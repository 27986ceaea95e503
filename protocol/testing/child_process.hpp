#pragma once
// Test support (tests only, never production): run an executable as a child process, find
// what ctest hands the tests (ARNAV_SOURCE_DIR, ARNAV_BINARY_DIR, ARNAV_DATA_DIR;
// cmake/ArnavCommon.cmake) and read small text files.
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

namespace arnav::testing {

struct CommandResult {
  int code = -1;       // exit status; -1 when the command could not run or was killed
  std::string output;  // stdout and stderr together
};

// Runs `command` through the shell with stderr folded into stdout.
inline CommandResult run_command(const std::string& command) {
  CommandResult r;
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf{};
  std::size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), pipe)) > 0) r.output.append(buf.data(), n);
  const int status = ::pclose(pipe);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

inline std::string required_env(const char* name) {
  const char* value = std::getenv(name);
  if (!value) throw std::runtime_error(std::string(name) + " is not set (run the test through ctest)");
  return value;
}

// An executable of the build tree, e.g. binary_path("appliance/app/arnav-appliance").
inline std::string binary_path(const std::string& relative) { return required_env("ARNAV_BINARY_DIR") + "/" + relative; }

// The repository's data/ folder.
inline std::string data_dir() { return required_env("ARNAV_DATA_DIR"); }

// The repository's root folder.
inline std::string source_dir() { return required_env("ARNAV_SOURCE_DIR"); }

// The whole content of a text file ("" when it cannot be read: tests compare it).
inline std::string read_text(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Writes `content` to a file in the temporary folder whose name carries `prefix`, the
// process id and `name`, and returns its path (the caller removes it).
inline std::filesystem::path write_temp_file(const std::string& prefix, const std::string& name, const std::string& content) {
  auto path = std::filesystem::temp_directory_path() / (prefix + "_" + std::to_string(::getpid()) + "_" + name);
  std::ofstream(path, std::ios::binary) << content;
  return path;
}

}  // namespace arnav::testing
