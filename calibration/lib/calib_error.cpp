#include "calibration/lib/calib_error.hpp"

#include <cerrno>
#include <cstring>
#include <ctime>
#include <cstdio>

namespace arnav::calib {

std::string read_text_file(const std::filesystem::path& path, const std::string& what) {
  // C stdio: GCC 12 flags istreambuf_iterator with a false -Wnull-dereference.
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) {
    throw CalibError(path.string() + ": cannot open " + what + " (" + std::strerror(errno) + ")");
  }
  std::string text;
  char buffer[65536];
  std::size_t n = 0;
  while ((n = std::fread(buffer, 1, sizeof buffer, f)) > 0) text.append(buffer, n);
  const bool failed = std::ferror(f) != 0;
  std::fclose(f);
  if (failed) throw CalibError(path.string() + ": read error in " + what);
  return text;
}

std::string utc_now_iso8601() {
  const std::time_t now = std::time(nullptr);
  std::tm tm_utc{};
  gmtime_r(&now, &tm_utc);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%SZ", &tm_utc);
  return text;
}

}  // namespace arnav::calib
