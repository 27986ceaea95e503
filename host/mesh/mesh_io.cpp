#include "host/mesh/mesh_io.hpp"

#include <filesystem>
#include <fstream>
#include <sstream>

#include "host/mesh/load_error.hpp"
#include "host/mesh/mesh_formats.hpp"
#include "host/mesh/vtk_legacy.hpp"

namespace arnav::host {
namespace {

std::string extension_of(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  if (!ext.empty()) ext.erase(0, 1);
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

std::ofstream open_out(const std::string& path) {
  std::ofstream out(path, std::ios::binary);
  if (!out) throw LoadError(path + ": cannot open for writing. Fix: check that the folder exists and is writable");
  out.precision(17);  // exact round trip of doubles
  return out;
}

}  // namespace

std::string read_text_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw_load_error(path, 0, "cannot open the file", "check the path (relative paths in a scene are relative to the scene file)");
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

TriMesh parse_surface(std::string_view content, const std::string& source, const std::string& format, ElementLines* lines) {
  if (format == "obj") return parse_obj(content, source, lines);
  if (format == "off") return parse_off(content, source, lines);
  if (format == "ply") return parse_ply(content, source, lines);
  if (format == "vtk") return vtk_surface(parse_vtk_legacy(content, source), source, lines);
  throw_load_error(source, 0, "unknown surface format '." + format + "'", "use .obj, .off, .ply or legacy .vtk (POLYDATA)");
}

TriMesh load_surface(const std::string& path, SurfaceCheck* check) {
  const std::string content = read_text_file(path);
  ElementLines lines;
  TriMesh mesh = parse_surface(content, path, extension_of(path), &lines);
  const SurfaceCheck c = validate_closed_surface(mesh, path, lines);
  if (check) *check = c;
  return mesh;
}

TetMesh load_volume(const std::string& path, TetMeshCheck* check) {
  const std::string ext = extension_of(path);
  ElementLines lines;
  TetMesh mesh;
  std::string element_source = path;
  if (ext == "ele" || ext == "node") {
    const std::filesystem::path stem = std::filesystem::path(path).replace_extension();
    const std::string node_path = stem.string() + ".node", ele_path = stem.string() + ".ele";
    mesh = parse_tetgen(read_text_file(node_path), node_path, read_text_file(ele_path), ele_path, &lines);
    element_source = ele_path;
  } else if (ext == "msh") {
    mesh = parse_gmsh(read_text_file(path), path, &lines);
  } else if (ext == "vtk") {
    mesh = vtk_volume(parse_vtk_legacy(read_text_file(path), path), path, &lines);
  } else {
    throw_load_error(path, 0, "unknown volume mesh format '." + ext + "'", "use TetGen .node/.ele, Gmsh .msh or legacy .vtk (UNSTRUCTURED_GRID)");
  }
  const TetMeshCheck c = validate_tet_mesh(mesh, element_source, lines);
  if (check) *check = c;
  return mesh;
}

void write_vtk_volume(const std::string& path, const TetMesh& mesh, const Eigen::Matrix3Xd& x,
                      const std::vector<double>& cell_scalar, const std::string& scalar_name) {
  std::ofstream out = open_out(path);
  out << "# vtk DataFile Version 3.0\nARNav volume (mm)\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS " << x.cols() << " double\n";
  for (int i = 0; i < x.cols(); ++i) out << x(0, i) << ' ' << x(1, i) << ' ' << x(2, i) << '\n';
  out << "CELLS " << mesh.tets.size() << ' ' << 5 * mesh.tets.size() << '\n';
  for (const auto& t : mesh.tets) out << "4 " << t[0] << ' ' << t[1] << ' ' << t[2] << ' ' << t[3] << '\n';
  out << "CELL_TYPES " << mesh.tets.size() << '\n';
  for (std::size_t t = 0; t < mesh.tets.size(); ++t) out << "10\n";
  out << "CELL_DATA " << mesh.tets.size() << "\nSCALARS region int 1\nLOOKUP_TABLE default\n";
  for (std::size_t t = 0; t < mesh.tets.size(); ++t) out << (t < mesh.tet_region.size() ? mesh.tet_region[t] : 0) << '\n';
  if (!cell_scalar.empty()) {
    out << "SCALARS " << scalar_name << " double 1\nLOOKUP_TABLE default\n";
    for (double v : cell_scalar) out << v << '\n';
  }
  if (!out) throw LoadError(path + ": write failed. Fix: check free disk space");
}

void write_vtk_surface(const std::string& path, const Eigen::Matrix3Xd& x, const std::vector<std::array<int, 3>>& tris) {
  std::ofstream out = open_out(path);
  out << "# vtk DataFile Version 3.0\nARNav surface (mm)\nASCII\nDATASET POLYDATA\nPOINTS " << x.cols() << " double\n";
  for (int i = 0; i < x.cols(); ++i) out << x(0, i) << ' ' << x(1, i) << ' ' << x(2, i) << '\n';
  out << "POLYGONS " << tris.size() << ' ' << 4 * tris.size() << '\n';
  for (const auto& t : tris) out << "3 " << t[0] << ' ' << t[1] << ' ' << t[2] << '\n';
  if (!out) throw LoadError(path + ": write failed. Fix: check free disk space");
}

void write_obj(const std::string& path, const Eigen::Matrix3Xd& x, const std::vector<std::array<int, 3>>& tris) {
  std::ofstream out = open_out(path);
  out << "# ARNav surface, units mm\n";
  for (int i = 0; i < x.cols(); ++i) out << "v " << x(0, i) << ' ' << x(1, i) << ' ' << x(2, i) << '\n';
  for (const auto& t : tris) out << "f " << t[0] + 1 << ' ' << t[1] + 1 << ' ' << t[2] + 1 << '\n';
  if (!out) throw LoadError(path + ": write failed. Fix: check free disk space");
}

void write_vtk_lines(const std::string& path, const Eigen::Matrix3Xd& x, const std::vector<std::array<int, 2>>& segments,
                     const std::vector<double>& radius_mm) {
  std::ofstream out = open_out(path);
  out << "# vtk DataFile Version 3.0\nARNav vessel centerlines (mm)\nASCII\nDATASET POLYDATA\nPOINTS " << x.cols() << " double\n";
  for (int i = 0; i < x.cols(); ++i) out << x(0, i) << ' ' << x(1, i) << ' ' << x(2, i) << '\n';
  out << "LINES " << segments.size() << ' ' << 3 * segments.size() << '\n';
  for (const auto& s : segments) out << "2 " << s[0] << ' ' << s[1] << '\n';
  out << "POINT_DATA " << x.cols() << "\nSCALARS radius_mm double 1\nLOOKUP_TABLE default\n";
  for (double r : radius_mm) out << r << '\n';
  if (!out) throw LoadError(path + ": write failed. Fix: check free disk space");
}

}  // namespace arnav::host
