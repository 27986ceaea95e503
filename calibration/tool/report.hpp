#pragma once
// The readable report every arnav-calib command writes: text lines collected while the
// command runs, printed to stdout and saved as report.txt in the output folder.
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

namespace arnav::calib::tool {

class Report {
 public:
  Report(std::filesystem::path out_dir, std::string command);
  // Appends one line (also echoed to stdout).
  void line(const std::string& text);
  template <typename... T>
  void kv(const std::string& key, const T&... values) {
    std::ostringstream s;
    s.precision(6);
    s << "  " << key << ": ";
    (s << ... << values);
    line(s.str());
  }
  void file(const std::filesystem::path& written, const std::string& what);
  // Writes report.txt; throws CalibError when it cannot.
  void save() const;
  const std::filesystem::path& out_dir() const { return out_dir_; }

 private:
  std::filesystem::path out_dir_;
  std::vector<std::string> lines_;
};

// Creates the output folder (throws CalibError naming it when impossible).
std::filesystem::path prepare_out_dir(const std::filesystem::path& dir);

}  // namespace arnav::calib::tool
