#include "calibration/tool/report.hpp"

#include <fstream>
#include <iostream>

#include "calibration/lib/calib_error.hpp"

namespace arnav::calib::tool {

Report::Report(std::filesystem::path out_dir, std::string command) : out_dir_(std::move(out_dir)) {
  line("ARNav calibration report: " + command);
  line("  date: " + utc_now_iso8601());
  line("  units: mm, degrees in reports (radians in files), pixels for images");
}

void Report::line(const std::string& text) {
  lines_.push_back(text);
  std::cout << text << "\n";
}

void Report::file(const std::filesystem::path& written, const std::string& what) {
  line("  wrote " + written.string() + " (" + what + ")");
}

void Report::save() const {
  const auto path = out_dir_ / "report.txt";
  std::ofstream out(path);
  for (const auto& l : lines_) out << l << "\n";
  out << "  wrote " << path.string() << " (this report)\n";
  if (!out) throw CalibError(path.string() + ": cannot write the report");
  std::cout << "  wrote " << path.string() << " (this report)\n";
}

std::filesystem::path prepare_out_dir(const std::filesystem::path& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec || !std::filesystem::is_directory(dir)) {
    throw CalibError(dir.string() + ": cannot create the output folder (" + ec.message() + ")");
  }
  return dir;
}

}  // namespace arnav::calib::tool
