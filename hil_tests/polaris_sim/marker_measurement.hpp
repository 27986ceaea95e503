#pragma once
// How the simulated Polaris measures a tool (docs/hil.md, "Sensor errors"): a real
// Polaris triangulates each marker sphere with noise, then fits the tool's marker geometry
// (the ROM's) to the measured spheres; the pose it reports is that fit, and its "RMS error"
// field is the fit's residual. `realistic` does the same: Gaussian noise on each marker
// (isotropic, marker_noise_rms_mm = 3-D RMS, so sigma per axis = RMS / sqrt(3)), the pose
// from the noisy markers by a rigid point-set fit (Umeyama, no scale), the RMS error field
// from the fit's residuals, and a tool missing for a whole frame with probability
// dropout_rate. `ideal` reports the true pose (the bench before issue 21; protocol tests).
// Random numbers are a function of (seed, tool, frame) only, so a frame asked twice (TX
// then BX, or a replayed frame number) reports the same measurement, and a run is
// repeatable from its seed. Not modelled: anisotropic (depth) noise, volume-dependent bias,
// marker occlusion of single spheres, stray markers.
#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>

namespace arnav::hil {

struct MeasurementModel {
  bool ideal = true;                 // true: the true pose, the scenario's rms_error_mm, no dropouts
  double marker_noise_rms_mm = 0.25; // per marker, 3-D RMS
  double dropout_rate = 0.0;         // probability that a tool is MISSING in a frame, [0, 1)
  std::uint64_t seed = 1;

  static MeasurementModel realistic(std::uint64_t seed = 1) { return {false, 0.25, 0.002, seed}; }
  std::string describe() const;      // one line for logs and summaries
};

struct MarkerFit {
  Eigen::Isometry3d X_NdiTool = Eigen::Isometry3d::Identity();
  double rms_error_mm = 0.0;         // RMS of |X_NdiTool * marker_i - measured_i|
};

// Rigid least-squares fit (no scale) of the tool's marker geometry (Tool frame) to the
// measured markers (Ndi frame). Needs >= 3 non-collinear markers and equal counts; throws
// std::invalid_argument naming what is wrong.
MarkerFit fit_tool_pose(const std::vector<Eigen::Vector3d>& markers_Tool_mm, const std::vector<Eigen::Vector3d>& measured_Ndi_mm);

// The markers of a passive NDI .rom (count at byte 28, float32 x,y,z from byte 72, the
// layout of the files in data/ndi_roms/); nullopt when the file holds fewer than 3
// markers, collinear ones (no orientation), or non-finite values.
std::optional<std::vector<Eigen::Vector3d>> rom_marker_positions(const std::vector<std::uint8_t>& rom);

// A planar four-sphere geometry (50-130 mm spread, like NDI's passive tools) for tools
// without a usable ROM or markers_mm.
std::vector<Eigen::Vector3d> default_marker_geometry();

// True when >= 3 markers and not (nearly) collinear.
bool markers_define_a_pose(const std::vector<Eigen::Vector3d>& markers_mm);

// The random stream of (seed, tool, frame).
std::mt19937_64 measurement_rng(std::uint64_t seed, int tool_index, std::uint32_t frame);

// One frame's measurement of a tool at its true pose. nullopt: dropped out (MISSING).
// `ideal` returns the true pose with rms_error_mm = ideal_rms_mm.
std::optional<MarkerFit> measure_tool(const MeasurementModel& model, const Eigen::Isometry3d& X_NdiTool_true,
                                      const std::vector<Eigen::Vector3d>& markers_Tool_mm, int tool_index,
                                      std::uint32_t frame, double ideal_rms_mm);

}  // namespace arnav::hil
