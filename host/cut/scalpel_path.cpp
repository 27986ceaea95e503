#include "host/cut/scalpel_path.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>

#include "host/mesh/load_error.hpp"

namespace arnav::host::cut {

namespace {

std::string trim(std::string s) {
  const auto not_space = [](unsigned char c) { return !std::isspace(c); };
  s.erase(s.begin(), std::find_if(s.begin(), s.end(), not_space));
  s.erase(std::find_if(s.rbegin(), s.rend(), not_space).base(), s.end());
  return s;
}

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out;
  std::string field;
  std::istringstream in(line);
  while (std::getline(in, field, ',')) out.push_back(trim(field));
  if (!line.empty() && line.back() == ',') out.emplace_back();
  return out;
}

}  // namespace

ScalpelPath parse_scalpel_csv(const std::string& text, const std::string& source) {
  static const char* kColumns[] = {"t_s", "tip_x", "tip_y", "tip_z", "heel_x", "heel_y", "heel_z"};
  const std::string expected = "t_s,tip_x,tip_y,tip_z,heel_x,heel_y,heel_z[,cutting]";
  ScalpelPath path;
  std::istringstream in(text);
  std::string line;
  int line_no = 0;
  bool header = false, with_cutting = false;
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (trim(line).empty() || trim(line)[0] == '#') continue;
    const std::vector<std::string> fields = split(line);
    if (!header) {
      bool ok = fields.size() == 7 || fields.size() == 8;
      for (std::size_t i = 0; ok && i < 7; ++i) ok = fields[i] == kColumns[i];
      if (ok && fields.size() == 8) ok = fields[7] == "cutting";
      if (!ok) throw_load_error(source, line_no, "the header is '" + trim(line) + "'", "start the file with the header " + expected);
      header = true;
      with_cutting = fields.size() == 8;
      continue;
    }
    const std::size_t columns = with_cutting ? 8 : 7;
    if (fields.size() != columns) {
      throw_load_error(source, line_no, "expected " + std::to_string(columns) + " comma-separated values, found " + std::to_string(fields.size()),
                       "write one value per header column: " + expected);
    }
    double v[7];
    for (std::size_t i = 0; i < 7; ++i) {
      const std::string& f = fields[i];
      double value = 0.0;
      const auto [end, ec] = std::from_chars(f.data(), f.data() + f.size(), value);
      if (f.empty() || ec != std::errc() || end != f.data() + f.size()) {
        throw_load_error(source, line_no, std::string(kColumns[i]) + " is '" + f + "', not a number", "write a decimal number (mm, s)");
      }
      if (!std::isfinite(value)) throw_load_error(source, line_no, std::string(kColumns[i]) + " is not finite", "write a finite number");
      v[i] = value;
    }
    ScalpelSample s;
    s.t_s = v[0];
    s.blade.tip_World_mm = Eigen::Vector3d(v[1], v[2], v[3]);
    s.blade.heel_World_mm = Eigen::Vector3d(v[4], v[5], v[6]);
    if (with_cutting) {
      if (fields[7] != "0" && fields[7] != "1") throw_load_error(source, line_no, "cutting is '" + fields[7] + "'", "write 1 (cut) or 0 (push)");
      s.cutting = fields[7] == "1";
    }
    if ((s.blade.tip_World_mm - s.blade.heel_World_mm).norm() <= 0.0) {
      throw_load_error(source, line_no, "tip and heel are the same point", "give two distinct points along the blade edge");
    }
    if (!path.samples.empty() && !(s.t_s > path.samples.back().t_s)) {
      throw_load_error(source, line_no, "t_s = " + fields[0] + " does not increase", "sort the rows by time, without repeated times");
    }
    path.samples.push_back(s);
  }
  if (!header) throw_load_error(source, 0, "the file is empty", "write the header " + expected + " and one row per sample");
  if (path.samples.empty()) throw_load_error(source, line_no, "the path has no samples", "add at least one row after the header");
  return path;
}

ScalpelPath load_scalpel_csv(const std::string& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw_load_error(file, 0, "cannot read the scalpel path", "check the path and permissions");
  std::ostringstream text;
  text << in.rdbuf();
  return parse_scalpel_csv(text.str(), file);
}

ScalpelSample ScalpelPath::at(double t) const {
  if (samples.empty()) return {};
  if (t <= samples.front().t_s) return samples.front();
  if (t >= samples.back().t_s) return samples.back();
  const auto it = std::upper_bound(samples.begin(), samples.end(), t, [](double tt, const ScalpelSample& s) { return tt < s.t_s; });
  const ScalpelSample& b = *it;
  const ScalpelSample& a = *(it - 1);
  const double u = (t - a.t_s) / (b.t_s - a.t_s);
  ScalpelSample s;
  s.t_s = t;
  s.blade.tip_World_mm = (1 - u) * a.blade.tip_World_mm + u * b.blade.tip_World_mm;
  s.blade.heel_World_mm = (1 - u) * a.blade.heel_World_mm + u * b.blade.heel_World_mm;
  s.cutting = a.cutting;
  return s;
}

}  // namespace arnav::host::cut
