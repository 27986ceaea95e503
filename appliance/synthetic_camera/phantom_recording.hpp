#pragma once
// Phantom recording of the bench: a reference simulation of the liver phantom deforming
// under a simulated tool (written by hil_tests' arnav-phantom-record), read by the
// synthetic camera (which films the deforming organ) and the simulated Polaris (which
// tracks the tool that deforms it). Text, one item per line, so errors name a line:
//
//   # arnav phantom recording 1
//   frame Model                      the organ's model frame (the scene's World), mm
//   tools 1 grasper                  tool count and names
//   targets 2 tumour_centroid p1     interior ground-truth points (first: the tumour centroid)
//   vertices 4996                    organ surface vertex count
//   faces 9988                       then one 'f a b c' line per triangle (0-based, outward)
//   f 0 1 2
//   frames 120                       then per frame:
//   t 0.000000                         time, s (strictly increasing)
//   tool grasper x y z qw qx qy qz     X_ModelTool per tool, in the declared order
//   target tumour_centroid x y z       per target, in the declared order
//   v x y z                            per vertex
//
// Lines starting with '#' after the first and blank lines are ignored.
#include <Eigen/Geometry>

#include <filesystem>
#include <ostream>
#include <stdexcept>
#include <string>
#include <vector>

namespace arnav::camera_sim {

class PhantomError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct PhantomFrame {
  double t_s = 0.0;
  std::vector<Eigen::Isometry3d> X_ModelTool;         // per tool
  std::vector<Eigen::Vector3d> targets_Model_mm;      // per target
  Eigen::Matrix3Xd vertices_Model_mm;                 // 3 x vertex count
};

struct PhantomRecording {
  int version = 1;
  std::vector<std::string> tool_names;
  std::vector<std::string> target_names;              // first: the tumour centroid
  int vertex_count = 0;
  std::vector<Eigen::Vector3i> faces;
  std::vector<PhantomFrame> frames;

  double duration_s() const { return frames.empty() ? 0.0 : frames.back().t_s; }
  // The phantom at time t_s: linear interpolation between the recorded frames (tool
  // rotations by slerp), held at the first/last frame outside the recording.
  PhantomFrame at(double t_s) const;
  // Only tool `index`'s pose at t_s (same interpolation; no surface work).
  Eigen::Isometry3d tool_pose_at(double t_s, int index) const;
  int tool_index(const std::string& name) const;  // -1 when absent
};

// Throws PhantomError "<source>:<line>: <what> (<fix>)" for a wrong header or version,
// a missing or misordered line, a bad number (non-finite too), a face index out of range,
// a degenerate face, a non-unit quaternion, times not increasing, a count out of range or
// a truncated file.
PhantomRecording parse_phantom_recording(const std::string& text, const std::string& source);
PhantomRecording read_phantom_recording(const std::filesystem::path& path);

// Checks the recording is consistent (counts match), then writes it; micrometre precision.
void write_phantom_recording(std::ostream& out, const PhantomRecording& recording);
void write_phantom_recording(const std::filesystem::path& path, const PhantomRecording& recording);

}  // namespace arnav::camera_sim
