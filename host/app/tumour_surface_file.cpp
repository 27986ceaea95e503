#include "host/app/tumour_surface_file.hpp"

#include <bit>
#include <cstring>
#include <fstream>
#include <istream>
#include <ostream>
#include <vector>

namespace arnav::host {
namespace {

constexpr const char* kHeader = "arnav tumour surface 1";
constexpr std::int32_t kMaxCount = 1'000'000;  // a tumour has ~10^3 vertices
static_assert(std::endian::native == std::endian::little, "tumour_Cam.bin is written and read little-endian");

template <typename T>
void put(std::ostream& out, T v) {
  out.write(reinterpret_cast<const char*>(&v), sizeof v);
}

template <typename T>
bool get(std::istream& in, T& v) {
  return static_cast<bool>(in.read(reinterpret_cast<char*>(&v), sizeof v));
}

}  // namespace

void write_tumour_surface_header(std::ostream& out) { out << kHeader << '\n'; }

void write_tumour_surface(std::ostream& out, std::int64_t camera_sequence, const TriMesh& s, bool with_triangles) {
  put<std::int64_t>(out, camera_sequence);
  put<std::int32_t>(out, static_cast<std::int32_t>(s.positions_World_mm.cols()));
  put<std::int32_t>(out, with_triangles ? static_cast<std::int32_t>(s.tris.size()) : 0);
  for (Eigen::Index i = 0; i < s.positions_World_mm.cols(); ++i)
    for (int k = 0; k < 3; ++k) put<float>(out, static_cast<float>(s.positions_World_mm(k, i)));
  if (with_triangles)
    for (const auto& t : s.tris)
      for (int k = 0; k < 3; ++k) put<std::int32_t>(out, t[static_cast<std::size_t>(k)]);
}

std::map<std::int64_t, TriMesh> read_tumour_surfaces(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw TumourSurfaceFileError(path + ": cannot read (arnav-host --record writes tumour_Cam.bin)");
  return parse_tumour_surfaces(in, path);
}

std::map<std::int64_t, TriMesh> parse_tumour_surfaces(std::istream& in, const std::string& path) {
  std::string header;
  std::getline(in, header);
  if (header != kHeader) throw TumourSurfaceFileError(path + ": not a tumour surface file (first line '" + header + "', expected '" + kHeader + "')");
  std::map<std::int64_t, TriMesh> out;
  std::vector<std::array<int, 3>> tris;
  for (int record = 1;; ++record) {
    const std::string where = path + ": record " + std::to_string(record);
    std::int64_t seq = 0;
    if (!get(in, seq)) break;  // clean end
    std::int32_t nv = 0, nt = 0;
    if (!get(in, nv) || !get(in, nt)) throw TumourSurfaceFileError(where + ": truncated (counts)");
    if (nv < 3 || nv > kMaxCount || nt < 0 || nt > kMaxCount)
      throw TumourSurfaceFileError(where + ": bad counts (" + std::to_string(nv) + " vertices, " + std::to_string(nt) + " triangles)");
    TriMesh m;
    m.positions_World_mm.resize(3, nv);
    for (std::int32_t i = 0; i < nv; ++i)
      for (int k = 0; k < 3; ++k) {
        float f = 0;
        if (!get(in, f)) throw TumourSurfaceFileError(where + ": truncated (vertices)");
        m.positions_World_mm(k, i) = f;
      }
    if (nt > 0) {
      tris.assign(static_cast<std::size_t>(nt), {});
      for (auto& t : tris)
        for (int k = 0; k < 3; ++k) {
          std::int32_t v = 0;
          if (!get(in, v)) throw TumourSurfaceFileError(where + ": truncated (triangles)");
          t[static_cast<std::size_t>(k)] = v;
        }
    } else if (tris.empty()) {
      throw TumourSurfaceFileError(where + ": no triangles and no earlier record to take them from");
    }
    for (const auto& t : tris)
      for (int v : t)
        if (v < 0 || v >= nv) throw TumourSurfaceFileError(where + ": a triangle indexes vertex " + std::to_string(v) + " of " + std::to_string(nv));
    m.tris = tris;
    out[seq] = std::move(m);
  }
  return out;
}

}  // namespace arnav::host
