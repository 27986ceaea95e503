#pragma once
// tumour_Cam.bin (arnav-host --record): the drawn tumour's surface in the camera frame, one
// record per frame it was drawn, for the bench's tumour surface distance
// (hil_tests/scenarios/ar_error.hpp). Little-endian binary after one text line:
//   "arnav tumour surface 1\n"
//   per record: int64 camera_sequence, int32 vertex_count, int32 triangle_count (0: the
//   previous record's triangles), float32 x,y,z per vertex (mm, Cam), int32 a,b,c per triangle.
// The reader checks counts, indices and truncation and names the file and record.
#include <cstdint>
#include <iosfwd>
#include <istream>
#include <map>
#include <stdexcept>
#include <string>

#include "host/mesh/tet_mesh.hpp"

namespace arnav::host {

void write_tumour_surface_header(std::ostream& out);
void write_tumour_surface(std::ostream& out, std::int64_t camera_sequence, const TriMesh& surface_Cam, bool with_triangles);

class TumourSurfaceFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// camera_sequence -> the surface (positions in Cam, mm). Throws TumourSurfaceFileError
// naming `source` (the file) and the record.
std::map<std::int64_t, TriMesh> read_tumour_surfaces(const std::string& path);
std::map<std::int64_t, TriMesh> parse_tumour_surfaces(std::istream& in, const std::string& source);

}  // namespace arnav::host
