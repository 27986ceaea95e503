#include "host/register/point_files.hpp"

#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <set>

#include "host/mesh/load_error.hpp"
#include "host/mesh/mesh_io.hpp"

namespace arnav::host {
namespace {

std::string_view trim(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
  return s;
}

struct Row {
  int line = 0;
  std::vector<std::string_view> fields;
};

// CSV rows after the header, which must equal `header` (spaces around fields ignored).
std::vector<Row> csv_rows(std::string_view content, const std::string& source, const std::vector<std::string>& header) {
  std::vector<Row> rows;
  bool have_header = false;
  int line_no = 0;
  std::size_t pos = 0;
  std::string expected;
  for (const auto& h : header) expected += (expected.empty() ? "" : ",") + h;
  while (pos < content.size()) {
    std::size_t end = content.find('\n', pos);
    if (end == std::string_view::npos) end = content.size();
    const std::string_view line = trim(content.substr(pos, end - pos));
    pos = end + 1;
    ++line_no;
    if (line.empty() || line.front() == '#') continue;
    Row r{line_no, {}};
    std::size_t a = 0;
    while (true) {
      const std::size_t b = line.find(',', a);
      r.fields.push_back(trim(line.substr(a, b == std::string_view::npos ? std::string_view::npos : b - a)));
      if (b == std::string_view::npos) break;
      a = b + 1;
    }
    if (!have_header) {
      bool ok = r.fields.size() == header.size();
      for (std::size_t k = 0; ok && k < header.size(); ++k) ok = r.fields[k] == header[k];
      if (!ok) throw_load_error(source, line_no, "expected the header '" + expected + "', found '" + std::string(line) + "'", "start the file with that header line");
      have_header = true;
      continue;
    }
    if (r.fields.size() != header.size())
      throw_load_error(source, line_no, "expected " + std::to_string(header.size()) + " comma-separated fields (" + expected + "), found " +
                                            std::to_string(r.fields.size()), "give every row all fields");
    rows.push_back(std::move(r));
  }
  if (!have_header) throw_load_error(source, 0, "the file is empty (no header '" + expected + "')", "write the header and one row per point");
  return rows;
}

double number(const Row& r, std::size_t k, const std::string& source, const std::string& column) {
  std::string_view s = r.fields[k];
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  double v = 0.0;
  const auto res = std::from_chars(s.data(), s.data() + s.size(), v);
  if (s.empty() || res.ec != std::errc() || res.ptr != s.data() + s.size())
    throw_load_error(source, r.line, column + " '" + std::string(r.fields[k]) + "' is not a number", "write millimetres as plain decimals");
  if (!std::isfinite(v)) throw_load_error(source, r.line, column + " is not finite", "write a finite coordinate in mm");
  return v;
}

void check_name(const Row& r, std::set<std::string>& seen, const std::string& source, const char* what) {
  const std::string name(r.fields[0]);
  if (name.empty()) throw_load_error(source, r.line, std::string(what) + " without a name", "name every row");
  if (!seen.insert(name).second)
    throw_load_error(source, r.line, std::string(what) + " name '" + name + "' appears twice", "give every row its own name");
}

}  // namespace

std::vector<Landmark> parse_landmarks(std::string_view content, const std::string& source) {
  const std::vector<std::string> header = {"name", "model_x", "model_y", "model_z", "intraop_x", "intraop_y", "intraop_z"};
  std::vector<Landmark> out;
  std::set<std::string> seen;
  for (const Row& r : csv_rows(content, source, header)) {
    check_name(r, seen, source, "landmark");
    Landmark l;
    l.name = std::string(r.fields[0]);
    l.line = r.line;
    for (int k = 0; k < 3; ++k) {
      l.p_Model_mm[k] = number(r, static_cast<std::size_t>(1 + k), source, header[static_cast<std::size_t>(1 + k)]);
      l.p_Intraop_mm[k] = number(r, static_cast<std::size_t>(4 + k), source, header[static_cast<std::size_t>(4 + k)]);
    }
    out.push_back(l);
  }
  if (out.size() < 3)
    throw_load_error(source, 0, "has " + std::to_string(out.size()) + " landmark(s); a rigid fit needs at least 3 (not on one line)",
                     "touch at least 3 well-spread landmarks, or leave out --landmarks");
  return out;
}

std::vector<Landmark> read_landmarks(const std::string& path) { return parse_landmarks(read_text_file(path), path); }

std::vector<NamedPoint> parse_targets(std::string_view content, const std::string& source) {
  const std::vector<std::string> header = {"name", "x_mm", "y_mm", "z_mm"};
  std::vector<NamedPoint> out;
  std::set<std::string> seen;
  for (const Row& r : csv_rows(content, source, header)) {
    check_name(r, seen, source, "target");
    NamedPoint p;
    p.name = std::string(r.fields[0]);
    p.line = r.line;
    for (int k = 0; k < 3; ++k) p.p_mm[k] = number(r, static_cast<std::size_t>(1 + k), source, header[static_cast<std::size_t>(1 + k)]);
    out.push_back(p);
  }
  return out;
}

std::vector<NamedPoint> read_targets(const std::string& path) { return parse_targets(read_text_file(path), path); }

void write_targets(const std::string& path, const std::vector<NamedPoint>& targets) {
  std::ofstream out(path);
  if (!out) throw LoadError(path + ": cannot open for writing. Fix: check that the folder exists and is writable");
  out.precision(10);
  out << "name,x_mm,y_mm,z_mm\n";
  for (const auto& t : targets) out << t.name << ',' << t.p_mm.x() << ',' << t.p_mm.y() << ',' << t.p_mm.z() << '\n';
  if (!out) throw LoadError(path + ": write failed. Fix: check free disk space");
}

}  // namespace arnav::host
