#include "host/register/point_cloud.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <optional>

#include "arnav/point_cloud_t.hpp"
#include "host/mesh/load_error.hpp"
#include "host/mesh/mesh_formats.hpp"
#include "host/mesh/mesh_io.hpp"

namespace arnav::host {
namespace {

std::string lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
  return s;
}

// Splits on commas, semicolons, spaces and tabs (runs of spaces count once; a comma
// between spaces too).
std::vector<std::string_view> split_fields(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t i = 0;
  auto is_sep = [](char c) { return c == ',' || c == ';' || c == ' ' || c == '\t' || c == '\r'; };
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    if (i >= line.size()) break;
    std::size_t j = i;
    while (j < line.size() && !is_sep(line[j])) ++j;
    out.push_back(line.substr(i, j - i));
    // skip trailing blanks and at most one explicit separator
    while (j < line.size() && (line[j] == ' ' || line[j] == '\t' || line[j] == '\r')) ++j;
    if (j < line.size() && (line[j] == ',' || line[j] == ';')) {
      ++j;
      // an empty field between two separators ("1,,2") is an error the caller sees as ""
      std::size_t k = j;
      while (k < line.size() && (line[k] == ' ' || line[k] == '\t' || line[k] == '\r')) ++k;
      if (k >= line.size() || line[k] == ',' || line[k] == ';') out.push_back(std::string_view());
    }
    i = j;
  }
  return out;
}

std::optional<double> to_double(std::string_view s) {
  if (s.empty()) return std::nullopt;
  if (s.front() == '+') s.remove_prefix(1);
  double v = 0.0;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  if (r.ec != std::errc() || r.ptr != s.data() + s.size()) return std::nullopt;
  return v;
}

void normalise_normals(PointCloud& c, const std::vector<int>& lines_or_empty) {
  for (int i = 0; i < c.normals.cols(); ++i) {
    const double n = c.normals.col(i).norm();
    if (!(n > 1e-12)) {
      const int line = lines_or_empty.empty() ? 0 : lines_or_empty[static_cast<std::size_t>(i)];
      throw_load_error(c.source, line, "point " + std::to_string(i) + " has a zero-length normal",
                       "write unit normals, or drop the normal columns");
    }
    c.normals.col(i) /= n;
  }
}

PointCloud from_columns(std::vector<double>& xs, int width, const std::string& source) {
  PointCloud c;
  c.source = source;
  const int n = static_cast<int>(xs.size() / static_cast<std::size_t>(width));
  c.points_mm.resize(3, n);
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) c.points_mm(k, i) = xs[static_cast<std::size_t>(i * width + k)];
  return c;
}

// ---- .xyz / .txt / .csv ----
PointCloud parse_table(std::string_view content, const std::string& source) {
  // Column roles: 0..2 xyz, 3..5 normal, 6 id, -1 ignored.
  std::vector<int> roles;
  bool have_header = false;
  int width = 0;
  std::vector<double> xyz, nrm;
  std::vector<long long> ids;
  std::vector<int> lines;
  int line_no = 0;
  std::size_t pos = 0;
  while (pos <= content.size()) {
    std::size_t end = content.find('\n', pos);
    if (end == std::string_view::npos) end = content.size();
    std::string_view line = trim(content.substr(pos, end - pos));
    ++line_no;
    pos = end + 1;
    if (line.empty() || line.front() == '#' || line.rfind("//", 0) == 0) {
      if (end == content.size()) break;
      continue;
    }
    const std::vector<std::string_view> f = split_fields(line);
    if (roles.empty()) {
      // First data line: a header when its first field is not a number.
      if (!to_double(f.empty() ? std::string_view() : f[0])) {
        have_header = true;
        int found = 0;
        for (const auto& name : f) {
          const std::string n = lower(trim(name));
          int role = -1;
          static const char* names[] = {"x", "y", "z", "nx", "ny", "nz", "id"};
          for (int r = 0; r < 7; ++r)
            if (n == names[r] || n == std::string(names[r]) + "_mm") role = r;
          if (role >= 0 && std::find(roles.begin(), roles.end(), role) != roles.end())
            throw_load_error(source, line_no, "column '" + n + "' appears twice in the header", "name each column once");
          if (role >= 0) ++found;
          roles.push_back(role);
        }
        auto has = [&](int r) { return std::find(roles.begin(), roles.end(), r) != roles.end(); };
        if (!has(0) || !has(1) || !has(2))
          throw_load_error(source, line_no, "the header '" + std::string(line) + "' does not name the columns x, y and z",
                           "start the file with a header like 'x,y,z' or 'x,y,z,nx,ny,nz', or with no header and 3 or 6 numbers per line");
        const int nn = static_cast<int>(has(3)) + static_cast<int>(has(4)) + static_cast<int>(has(5));
        if (nn != 0 && nn != 3)
          throw_load_error(source, line_no, "the header names only part of the normal (nx, ny, nz)", "name all three normal columns or none");
        width = static_cast<int>(roles.size());
        if (end == content.size()) break;
        continue;
      }
      width = static_cast<int>(f.size());
      if (width != 3 && width != 6)
        throw_load_error(source, line_no,
                         "expected 3 numbers (x y z) or 6 (x y z nx ny nz) per line, found " + std::to_string(width),
                         "write one point per line, or add a header line naming the columns (x,y,z,nx,ny,nz,id)");
      for (int k = 0; k < width; ++k) roles.push_back(k);
    }
    if (static_cast<int>(f.size()) != width)
      throw_load_error(source, line_no,
                       "expected " + std::to_string(width) + " fields as on the first " + (have_header ? "header" : "data") +
                           " line, found " + std::to_string(f.size()),
                       "give every line the same columns");
    double p[3] = {0, 0, 0}, n[3] = {0, 0, 0};
    bool has_n = false;
    for (int k = 0; k < width; ++k) {
      const int role = roles[static_cast<std::size_t>(k)];
      if (role < 0) continue;
      if (role == 6) {
        long long id = 0;
        const auto r = std::from_chars(f[static_cast<std::size_t>(k)].data(),
                                       f[static_cast<std::size_t>(k)].data() + f[static_cast<std::size_t>(k)].size(), id);
        if (r.ec != std::errc() || r.ptr != f[static_cast<std::size_t>(k)].data() + f[static_cast<std::size_t>(k)].size())
          throw_load_error(source, line_no, "id '" + std::string(f[static_cast<std::size_t>(k)]) + "' is not an integer",
                           "write integer point ids");
        ids.push_back(id);
        continue;
      }
      const auto v = to_double(f[static_cast<std::size_t>(k)]);
      if (!v)
        throw_load_error(source, line_no, "field " + std::to_string(k + 1) + " '" + std::string(f[static_cast<std::size_t>(k)]) + "' is not a number",
                         "write plain decimal numbers (mm)");
      if (!std::isfinite(*v))
        throw_load_error(source, line_no, "field " + std::to_string(k + 1) + " is not finite (" + std::string(f[static_cast<std::size_t>(k)]) + ")",
                         "remove the point or fix the exporter (NaN/Inf usually marks a missing depth sample)");
      if (role < 3) {
        p[role] = *v;
      } else {
        n[role - 3] = *v;
        has_n = true;
      }
    }
    xyz.insert(xyz.end(), p, p + 3);
    if (has_n) nrm.insert(nrm.end(), n, n + 3);
    lines.push_back(line_no);
    if (end == content.size()) break;
  }
  PointCloud c = from_columns(xyz, 3, source);
  if (!nrm.empty()) {
    c.normals = Eigen::Map<Eigen::Matrix3Xd>(nrm.data(), 3, static_cast<Eigen::Index>(nrm.size() / 3));
    normalise_normals(c, lines);
  }
  c.ids = std::move(ids);
  c.lines = std::move(lines);
  return c;
}

// ---- .ply ---- (the scene library's reader: ASCII and binary, both endiannesses)
PointCloud parse_ply_cloud(std::string_view content, const std::string& source) {
  PlyPoints ply = parse_ply_points(content, source, /*faces_required=*/false);
  PointCloud c;
  c.source = source;
  c.points_mm = std::move(ply.mesh.positions_World_mm);
  c.lines = std::move(ply.vertex_lines);
  if (ply.normals.cols() > 0) {
    c.normals = std::move(ply.normals);
    normalise_normals(c, c.lines);
  }
  if (std::all_of(c.lines.begin(), c.lines.end(), [](int l) { return l == 0; })) c.lines.clear();
  return c;
}

PointCloud from_surface(std::string_view content, const std::string& source, const std::string& format) {
  const TriMesh m = parse_surface(content, source, format, nullptr);
  PointCloud c;
  c.source = source;
  c.points_mm = m.positions_World_mm;
  for (int i = 0; i < c.points_mm.cols(); ++i)
    if (!c.points_mm.col(i).allFinite())
      throw_load_error(source, 0, "vertex " + std::to_string(i) + " is not finite", "remove invalid vertices");
  for (std::size_t t = 0; t < m.tris.size(); ++t)
    for (int v : m.tris[t])
      if (v < 0 || v >= c.points_mm.cols())
        throw_load_error(source, 0, "triangle " + std::to_string(t) + " uses vertex " + std::to_string(v) + " of " + std::to_string(c.points_mm.cols()),
                         "fix the face indices (or export the points only)");
  if (!m.tris.empty()) {
    Eigen::Matrix3Xd n = Eigen::Matrix3Xd::Zero(3, c.points_mm.cols());
    for (const auto& t : m.tris) {
      const Eigen::Vector3d a = c.points_mm.col(t[0]), b = c.points_mm.col(t[1]), d = c.points_mm.col(t[2]);
      const Eigen::Vector3d area_n = (b - a).cross(d - a);  // twice the area, along the normal
      for (int k = 0; k < 3; ++k) n.col(t[static_cast<std::size_t>(k)]) += area_n;
    }
    bool all = true;
    for (int i = 0; i < n.cols(); ++i) {
      const double len = n.col(i).norm();
      if (len > 1e-12) n.col(i) /= len;
      else all = false;
    }
    if (all) c.normals = n;  // vertices without triangles: no normals for the cloud
  }
  return c;
}

}  // namespace

PointCloud parse_point_cloud(std::string_view content, const std::string& source, const std::string& format) {
  if (format == "xyz" || format == "txt" || format == "csv") return parse_table(content, source);
  if (format == "ply") return parse_ply_cloud(content, source);
  if (format == "obj" || format == "vtk") return from_surface(content, source, format);
  throw_load_error(source, 0, "unknown point-cloud format '." + format + "'", "use .xyz, .txt, .csv, .ply, .obj or .vtk");
}

PointCloud read_point_cloud(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  if (!ext.empty()) ext.erase(0, 1);
  return parse_point_cloud(read_text_file(path), path, lower(ext));
}

namespace {
// The generated decoder sizes its arrays from the counts in the message before reading
// them: walk the encoding first (LCM: 8-byte fingerprint, big-endian fields, strings as
// int32 length + bytes) and refuse counts the bytes cannot hold.
void check_cloud_counts(const unsigned char* b, std::size_t size, const std::string& channel) {
  std::size_t off = 8;
  auto fail = [&](const std::string& what) {
    throw_load_error(channel, 0, "point_cloud_t message of " + std::to_string(size) + " bytes: " + what,
                     "publish arnav.point_cloud_t as generated from protocol/lcm/point_cloud_t.lcm");
  };
  auto int32 = [&](const char* what) {
    if (size < 4 || off > size - 4) fail(std::string("ends before ") + what);
    const std::uint32_t v = (std::uint32_t{b[off]} << 24) | (std::uint32_t{b[off + 1]} << 16) | (std::uint32_t{b[off + 2]} << 8) | b[off + 3];
    off += 4;
    return static_cast<std::int32_t>(v);
  };
  auto skip = [&](std::size_t n, const char* what) {
    if (n > size || off > size - n) fail(std::string("ends inside ") + what);
    off += n;
  };
  for (const char* what : {"frame_name", "source"}) {
    const std::int32_t len = int32(what);
    if (len < 1) fail(std::string("bad length of ") + what + " (LCM strings carry their terminating zero)");
    skip(static_cast<std::size_t>(len), what);
  }
  skip(32, "the time stamps");
  const struct {
    const char* name;
    std::size_t bytes;
  } arrays[] = {{"num_points", 24}, {"num_normals", 24}, {"num_ids", 8}};
  for (const auto& a : arrays) {
    const std::int32_t n = int32(a.name);
    if (n < 0 || static_cast<std::size_t>(n) > (size - off) / a.bytes)
      fail(std::string(a.name) + " " + std::to_string(n) + " exceeds what the remaining " + std::to_string(size - off) + " bytes hold");
    skip(static_cast<std::size_t>(n) * a.bytes, a.name);
  }
}
}  // namespace

PointCloud decode_point_cloud_message(const void* data, std::size_t size, const std::string& channel) {
  check_cloud_counts(static_cast<const unsigned char*>(data), size, channel);
  arnav::point_cloud_t m;
  if (size > static_cast<std::size_t>(std::numeric_limits<int>::max()) || m.decode(data, 0, static_cast<int>(size)) < 0)
    throw_load_error(channel, 0, "undecodable point_cloud_t message (" + std::to_string(size) + " bytes)",
                     "publish arnav.point_cloud_t as generated from protocol/lcm/point_cloud_t.lcm");
  const std::string where = channel + " message " + std::to_string(m.sequence);
  if (m.num_normals != 0 && m.num_normals != m.num_points)
    throw_load_error(where, 0, "num_normals " + std::to_string(m.num_normals) + " is neither 0 nor num_points " + std::to_string(m.num_points),
                     "send one normal per point or none");
  if (m.num_ids != 0 && m.num_ids != m.num_points)
    throw_load_error(where, 0, "num_ids " + std::to_string(m.num_ids) + " is neither 0 nor num_points " + std::to_string(m.num_points),
                     "send one id per point or none");
  PointCloud c;
  c.source = where + " (" + m.source + ", frame " + m.frame_name + ")";
  c.frame_name = m.frame_name;
  c.sequence = m.sequence;
  c.points_mm.resize(3, m.num_points);
  for (int i = 0; i < m.num_points; ++i)
    for (int k = 0; k < 3; ++k) {
      const double v = m.p_mm[static_cast<std::size_t>(i)][static_cast<std::size_t>(k)];
      if (!std::isfinite(v)) throw_load_error(where, 0, "point " + std::to_string(i) + " is not finite", "drop invalid samples before publishing");
      c.points_mm(k, i) = v;
    }
  if (m.num_normals > 0) {
    c.normals.resize(3, m.num_normals);
    for (int i = 0; i < m.num_normals; ++i)
      for (int k = 0; k < 3; ++k) c.normals(k, i) = m.normals[static_cast<std::size_t>(i)][static_cast<std::size_t>(k)];
    for (int i = 0; i < m.num_normals; ++i)
      if (!c.normals.col(i).allFinite())
        throw_load_error(where, 0, "normal " + std::to_string(i) + " is not finite", "send unit normals");
    normalise_normals(c, {});
  }
  c.ids.assign(m.ids.begin(), m.ids.end());
  return c;
}

double bounding_extent_mm(const Eigen::Matrix3Xd& points) {
  if (points.cols() == 0) return 0.0;
  return (points.rowwise().maxCoeff() - points.rowwise().minCoeff()).maxCoeff();
}

void check_cloud_units(const PointCloud& cloud, double model_extent_mm) {
  const double e = bounding_extent_mm(cloud.points_mm);
  if (cloud.size() >= 3 && model_extent_mm > 0.0 && e < model_extent_mm / 100.0 && e * 1000.0 > model_extent_mm / 20.0)
    throw_load_error(cloud.source, 0,
                     "the cloud spans " + std::to_string(e) + " units while the model spans " + std::to_string(model_extent_mm) +
                         " mm: it looks like metres",
                     "write the cloud in millimetres (multiply the coordinates by 1000)");
  if (cloud.size() >= 3 && model_extent_mm > 0.0 && e > model_extent_mm * 20.0)
    throw_load_error(cloud.source, 0,
                     "the cloud spans " + std::to_string(e) + " mm while the model spans " + std::to_string(model_extent_mm) +
                         " mm: wrong units (micrometres?) or wild outliers",
                     "write the cloud in millimetres and remove points far from the organ");
}

}  // namespace arnav::host
