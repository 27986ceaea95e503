#pragma once
// Ground truth of the synthetic camera, one CSV row per rendered board and frame, written
// beside the frames (ground_truth.csv):
//
//   # arnav camera ground truth 1
//   sequence,time_s,board,x_mm,y_mm,z_mm,qw,qx,qy,qz,tags_visible,frame_file
//   0,0.000000,liver_marker,12.5,-3.1,480.2,0.01,0.99,0.02,0.03,4,frame_000000.png
//
// Pose columns: X_CamBoard (Cam: OpenCV camera frame; Board: the board layout's frame),
// position in mm, quaternion w first. tags_visible: tags fully in the image, facing the
// camera and less than 10 % occluded. frame_file: empty when frames are not written.
//
// Version 2 (written when the camera films a deforming phantom, phantom_recording.hpp)
// adds two columns, u_px,v_px, and target rows: board = "target:NAME" (e.g.
// target:tumour_centroid), x/y/z_mm = the deformed target in Cam, quaternion identity,
// tags_visible = 1 when it projects into the image (in front of the lens) else 0, and
// u_px,v_px = its distorted pixel (the camera model's projection, as cv::projectPoints).
// Board rows leave u_px,v_px empty. Readers accept both versions.
#include <Eigen/Geometry>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace arnav::camera_sim {

struct GroundTruthRow {
  std::int64_t sequence = 0;
  double time_s = 0.0;
  std::string board;
  Eigen::Isometry3d X_CamBoard = Eigen::Isometry3d::Identity();
  int tags_visible = 0;
  std::string frame_file;
  bool has_px = false;          // version 2 target rows
  double u_px = 0.0, v_px = 0.0;
  bool is_target() const { return board.rfind("target:", 0) == 0; }
};

class GroundTruthError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class GroundTruthWriter {
 public:
  // Throws GroundTruthError naming the file when it cannot be created.
  // version: 1 (boards only) or 2 (u_px,v_px columns and target rows).
  explicit GroundTruthWriter(const std::filesystem::path& path, int version = 1);
  void write(const GroundTruthRow& row);  // flushed per frame: readers may follow the file
 private:
  std::filesystem::path path_;
  std::ofstream out_;
  int version_ = 1;
};

// Throws GroundTruthError "<source>:<line>: <what>" for a missing header, a wrong column
// count, a non-number or a non-unit quaternion.
std::vector<GroundTruthRow> parse_ground_truth(const std::string& text, const std::string& source);
std::vector<GroundTruthRow> read_ground_truth(const std::filesystem::path& path);

}  // namespace arnav::camera_sim
