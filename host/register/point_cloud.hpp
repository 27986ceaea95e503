#pragma once
// Intraoperative point clouds: points swabbed with the tracked pointer, a stereo or depth
// camera's surface, a partial surface exported from another tool. Frame: whatever the
// file is in (the intraoperative frame `Intraop` for arnav-register). Units: mm.
// Formats, chosen by extension:
//   .xyz .txt .csv  one point per line, "x y z" or "x,y,z" (comma, semicolon, space or tab
//                   separated), optionally followed by "nx ny nz"; '#' comments; an optional
//                   header line naming the columns (x,y,z[,nx,ny,nz][,id]).
//   .ply            ASCII or binary little-endian (as depth cameras and Open3D write them);
//                   vertex properties x y z [nx ny nz]; faces and other elements skipped.
//   .obj .vtk       surfaces (the scene loader's parsers): their vertices, with area-weighted
//                   vertex normals when they have triangles.
// Every error is a LoadError naming the file and the line (text) or byte offset (binary).
#include <Eigen/Core>

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace arnav::host {

struct PointCloud {
  Eigen::Matrix3Xd points_mm;              // one point per column
  Eigen::Matrix3Xd normals;                // unit normals per point, or 0 columns when absent
  std::vector<long long> ids;              // point ids (tracking), or empty
  std::vector<int> lines;                  // source line per point (0 for binary input)
  std::string source;
  std::string frame_name;                  // LCM messages only: the message's frame
  long long sequence = -1;                 // LCM messages only: the message's sequence number

  int size() const { return static_cast<int>(points_mm.cols()); }
  bool has_normals() const { return normals.cols() == points_mm.cols() && normals.cols() > 0; }
};

// Parses without touching the file system. `format` is the lower-case extension without
// the dot (xyz, txt, csv, ply, obj, vtk).
PointCloud parse_point_cloud(std::string_view content, const std::string& source, const std::string& format);

// Reads by extension. Throws LoadError naming the file.
PointCloud read_point_cloud(const std::string& path);

// Unit check against the model it will be registered to: a cloud whose extent is about a
// thousandth of the model's was written in metres. Throws LoadError naming the file, the
// two extents and the fix.
void check_cloud_units(const PointCloud& cloud, double model_extent_mm);

// A cloud received over LCM (arnav::point_cloud_t, channel ARNAV_CLOUD_<source>) from its
// encoded bytes: decodes, then checks the counts (normals and ids 0 or num_points), finite
// coordinates and non-zero normals. Throws LoadError naming the channel, the message's
// sequence number and the point.
PointCloud decode_point_cloud_message(const void* data, std::size_t size, const std::string& channel);

// Largest bounding-box side of a point set (mm); 0 when empty.
double bounding_extent_mm(const Eigen::Matrix3Xd& points);

}  // namespace arnav::host
