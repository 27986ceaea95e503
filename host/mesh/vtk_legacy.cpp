#include "host/mesh/vtk_legacy.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>

#include "host/mesh/load_error.hpp"
#include "host/mesh/text_cursor.hpp"

namespace arnav::host {
namespace {

std::string upper(std::string_view s) {
  std::string u(s);
  for (char& c : u) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return u;
}

// Printable prefix of a token, for messages about binary garbage.
std::string printable(std::string_view t) {
  std::string out;
  for (char c : t.substr(0, 24)) {
    if (std::isprint(static_cast<unsigned char>(c))) {
      out += c;
    } else {
      return "binary data";
    }
  }
  return "'" + out + "'";
}

// Connectivity block "n size" followed by size integers: n lists of (count, ids...).
std::vector<std::vector<int>> read_cells(TextCursor& in, bool binary, const char* keyword, std::vector<int>& lines) {
  const long long n = in.integer("cell count");
  const long long size = in.integer("connectivity size");
  const int header_line = in.line();
  if (n < 0 || size < n || size > static_cast<long long>(1) << 31)
    in.fail(std::string(keyword) + " counts " + std::to_string(n) + " " + std::to_string(size) + " are inconsistent",
            "the second number is the total of all lists including their lengths");
  std::vector<std::vector<int>> out;
  out.reserve(static_cast<std::size_t>(std::min<long long>(n, 1 << 20)));
  if (binary) in.skip_one_newline();
  long long used = 0;
  for (long long c = 0; c < n; ++c) {
    const long long count = binary ? in.be_int32("cell size") : in.integer("cell size");
    if (!binary) lines.push_back(in.line());
    else lines.push_back(0);
    used += count + 1;
    if (count < 1 || used > size)
      (binary ? in.fail_at_offset(std::string(keyword) + " cell " + std::to_string(c) + " has size " + std::to_string(count) +
                                      " which overruns the declared connectivity size " + std::to_string(size) + " (header line " +
                                      std::to_string(header_line) + ")",
                                  "the header counts do not match the data; re-export the file")
              : in.fail(std::string(keyword) + " cell " + std::to_string(c) + " has size " + std::to_string(count) +
                            " which overruns the declared connectivity size " + std::to_string(size),
                        "the header counts do not match the data; re-export the file"));
    std::vector<int> ids(static_cast<std::size_t>(count));
    for (auto& id : ids) id = binary ? in.be_int32("cell vertex index") : in.index("cell vertex index");
    out.push_back(std::move(ids));
  }
  if (used != size)
    in.fail(std::string(keyword) + " declares connectivity size " + std::to_string(size) + " but its lists use " +
                std::to_string(used),
            "fix the header counts (second number = total of list lengths + 1 per list)");
  return out;
}

}  // namespace

VtkLegacyData parse_vtk_legacy(std::string_view content, const std::string& source) {
  TextCursor in(content, source);
  const std::string_view magic = in.rest_of_line();
  if (magic.rfind("# vtk DataFile Version", 0) != 0)
    in.fail("not a legacy VTK file (first line must be '# vtk DataFile Version x.y')", "give a legacy .vtk file");
  const std::string version(magic.substr(22));
  const std::size_t digit = version.find_first_of("0123456789");
  if (digit != std::string::npos && std::atoi(version.c_str() + digit) >= 5)
    in.fail("legacy VTK version" + version + " (OFFSETS/CONNECTIVITY layout) is not supported",
            "save the file as legacy VTK 4.2 or earlier (vtkDataWriter::SetFileVersion(42))");
  in.skip_one_newline();
  in.rest_of_line();  // title
  in.skip_one_newline();
  const std::string format = upper(in.token("ASCII or BINARY"));
  if (format != "ASCII" && format != "BINARY") in.fail("third line must be ASCII or BINARY, found '" + format + "'", "fix the header");
  const bool binary = format == "BINARY";
  if (upper(in.token("DATASET")) != "DATASET") in.fail("expected 'DATASET <type>'", "fix the header");
  const std::string dataset = upper(in.token("dataset type"));
  VtkLegacyData out;
  if (dataset == "UNSTRUCTURED_GRID") {
    out.unstructured = true;
  } else if (dataset != "POLYDATA") {
    in.fail("dataset " + dataset + " is not supported", "use POLYDATA for surfaces or UNSTRUCTURED_GRID for tetrahedra");
  }
  bool have_points = false;
  std::string last_section = "the header";
  while (!in.at_end()) {
    const std::string_view raw = in.token("section keyword");
    const std::string key = upper(raw);
    if (key == "POINTS") {
      const long long n = in.integer("point count");
      const std::string type = upper(in.token("point type"));
      if (n < 0 || n > (1LL << 28)) in.fail("point count " + std::to_string(n) + " is out of range", "fix the count");
      if (type != "FLOAT" && type != "DOUBLE") in.fail("point type " + type + " is not supported", "use float or double");
      const bool dbl = type == "DOUBLE";
      last_section = "'POINTS " + std::to_string(n) + " " + type + "' (line " + std::to_string(in.line()) + ")";
      if (binary) {
        in.skip_one_newline();
        if (content.size() - in.offset() < static_cast<std::size_t>(n) * (dbl ? 24 : 12))
          in.fail_at_offset("POINTS declares " + std::to_string(n) + " points but the file ends before their data",
                            "fix the point count or re-export the file");
      }
      out.points.resize(3, n);
      for (long long i = 0; i < n; ++i)
        for (int k = 0; k < 3; ++k) {
          double v;
          if (binary) {
            v = dbl ? in.be_double("point coordinate") : static_cast<double>(in.be_float("point coordinate"));
            if (!std::isfinite(v))
              in.fail_at_offset("point " + std::to_string(i) + " has a NaN or infinite coordinate",
                                "repair the mesh (or check that the point count matches the data)");
          } else {
            v = in.real("point coordinate");
          }
          out.points(k, i) = v;
        }
      have_points = true;
    } else if (key == "POLYGONS" || key == "CELLS") {
      if ((key == "CELLS") != out.unstructured)
        in.fail(key + " does not belong to a " + dataset + " dataset", "use POLYGONS in POLYDATA, CELLS in UNSTRUCTURED_GRID");
      auto& dst = key == "CELLS" ? out.cells : out.polygons;
      last_section = "'" + key + "' (line " + std::to_string(in.line()) + ")";
      dst = read_cells(in, binary, key == "CELLS" ? "CELLS" : "POLYGONS", out.element_lines);
    } else if (key == "VERTICES" || key == "LINES" || key == "TRIANGLE_STRIPS") {
      std::vector<int> ignored_lines;
      last_section = "'" + key + "' (line " + std::to_string(in.line()) + ")";
      read_cells(in, binary, key.c_str(), ignored_lines);  // not part of a closed surface
    } else if (key == "CELL_TYPES") {
      const long long n = in.integer("cell type count");
      if (n != static_cast<long long>(out.cells.size()))
        in.fail("CELL_TYPES count " + std::to_string(n) + " differs from the CELLS count " + std::to_string(out.cells.size()),
                "give one type per cell, after CELLS");
      if (binary) in.skip_one_newline();
      out.cell_types.resize(static_cast<std::size_t>(n));
      for (auto& t : out.cell_types) t = binary ? in.be_int32("cell type") : in.index("cell type");
      last_section = "'CELL_TYPES'";
    } else if (key == "POINT_DATA" || key == "CELL_DATA" || key == "FIELD" || key == "METADATA") {
      break;  // attributes: not needed for geometry
    } else {
      if (binary && last_section != "the header")
        in.fail_at_offset("expected a section keyword (POINTS, POLYGONS, CELLS, CELL_TYPES, POINT_DATA) after the data of " +
                              last_section + ", found " + printable(raw),
                          "the counts in the file do not match its data (a count too small or too large); re-export the "
                          "file or correct the count");
      in.fail("unknown section " + printable(raw) + " after " + last_section,
              "expected POINTS, POLYGONS, CELLS, CELL_TYPES or POINT_DATA");
    }
  }
  if (!have_points) in.fail("the file has no POINTS section", "give the vertex coordinates in a POINTS section");
  if (out.unstructured && out.cell_types.size() != out.cells.size())
    in.fail("CELLS without matching CELL_TYPES", "add a CELL_TYPES section with one type per cell");
  return out;
}

TriMesh vtk_surface(const VtkLegacyData& data, const std::string& source, ElementLines* lines) {
  if (data.unstructured)
    throw_load_error(source, 0, "an UNSTRUCTURED_GRID was given where a surface is expected",
                     "give a POLYDATA surface, or use the file as the volume mesh");
  TriMesh out;
  out.positions_World_mm = data.points;
  for (std::size_t p = 0; p < data.polygons.size(); ++p) {
    const auto& poly = data.polygons[p];
    if (poly.size() < 3)
      throw_load_error(source, p < data.element_lines.size() ? data.element_lines[p] : 0,
                       "polygon " + std::to_string(p) + " has fewer than 3 vertices", "remove it");
    for (std::size_t k = 1; k + 1 < poly.size(); ++k) {
      out.tris.push_back({poly[0], poly[k], poly[k + 1]});
      if (lines) lines->push_back(p < data.element_lines.size() ? data.element_lines[p] : 0);
    }
  }
  return out;
}

TetMesh vtk_volume(const VtkLegacyData& data, const std::string& source, ElementLines* lines) {
  if (!data.unstructured)
    throw_load_error(source, 0, "a POLYDATA surface was given where a volume mesh is expected",
                     "give an UNSTRUCTURED_GRID of tetrahedra, or generate the volume with TetGen");
  TetMesh out;
  out.rest_positions_World_mm = data.points;
  for (std::size_t c = 0; c < data.cells.size(); ++c) {
    const int type = data.cell_types[c];
    const int line = c < data.element_lines.size() ? data.element_lines[c] : 0;
    if (type == 1 || type == 3 || type == 5) continue;  // vertex, line, triangle: boundary data
    if (type != 10)
      throw_load_error(source, line,
                       "cell " + std::to_string(c) + " has VTK type " + std::to_string(type) + "; only linear tetrahedra (10) are supported",
                       "convert the mesh to linear tetrahedra");
    if (data.cells[c].size() != 4)
      throw_load_error(source, line, "tetrahedron cell " + std::to_string(c) + " has " + std::to_string(data.cells[c].size()) + " vertices",
                       "a linear tetrahedron has 4");
    out.tets.push_back({data.cells[c][0], data.cells[c][1], data.cells[c][2], data.cells[c][3]});
    if (lines) lines->push_back(line);
  }
  return out;
}

}  // namespace arnav::host
