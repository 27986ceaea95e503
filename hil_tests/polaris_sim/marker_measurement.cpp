#include "hil_tests/polaris_sim/marker_measurement.hpp"

#include <cmath>
#include <cstring>
#include <sstream>
#include <stdexcept>

#include <Eigen/SVD>

namespace arnav::hil {
namespace {

constexpr std::size_t kRomMarkerCountOffset = 28;
constexpr std::size_t kRomMarkerOffset = 72;
constexpr std::size_t kRomMaxMarkers = 20;

std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

float read_float_le(const std::vector<std::uint8_t>& b, std::size_t at) {
  const std::uint32_t u = static_cast<std::uint32_t>(b[at]) | static_cast<std::uint32_t>(b[at + 1]) << 8 |
                          static_cast<std::uint32_t>(b[at + 2]) << 16 | static_cast<std::uint32_t>(b[at + 3]) << 24;
  float f = 0.0f;
  std::memcpy(&f, &u, sizeof f);
  return f;
}

}  // namespace

std::string MeasurementModel::describe() const {
  if (ideal) return "ideal (true pose, no marker noise, no dropouts)";
  std::ostringstream s;
  s << "realistic (marker noise " << marker_noise_rms_mm << " mm RMS 3-D per marker, pose fitted to the noisy markers, dropout rate "
    << dropout_rate << " per tool and frame, seed " << seed << ")";
  return s.str();
}

bool markers_define_a_pose(const std::vector<Eigen::Vector3d>& m) {
  if (m.size() < 3) return false;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& p : m) c += p;
  c /= static_cast<double>(m.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : m) cov += (p - c) * (p - c).transpose();
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(cov);
  const Eigen::Vector3d s = svd.singularValues();
  // The second spread must be a real one (>= 1 mm RMS off the main axis).
  return std::isfinite(s[0]) && s[1] / static_cast<double>(m.size()) >= 1.0;
}

MarkerFit fit_tool_pose(const std::vector<Eigen::Vector3d>& markers_Tool_mm, const std::vector<Eigen::Vector3d>& measured_Ndi_mm) {
  if (markers_Tool_mm.size() != measured_Ndi_mm.size())
    throw std::invalid_argument("fit_tool_pose: " + std::to_string(markers_Tool_mm.size()) + " tool markers but " +
                                std::to_string(measured_Ndi_mm.size()) + " measured ones");
  if (!markers_define_a_pose(markers_Tool_mm))
    throw std::invalid_argument("fit_tool_pose: the tool's markers are fewer than 3 or collinear (no orientation)");
  const auto n = static_cast<Eigen::Index>(markers_Tool_mm.size());
  Eigen::Matrix3Xd src(3, n), dst(3, n);
  for (Eigen::Index i = 0; i < n; ++i) {
    src.col(i) = markers_Tool_mm[static_cast<std::size_t>(i)];
    dst.col(i) = measured_Ndi_mm[static_cast<std::size_t>(i)];
  }
  if (!dst.allFinite()) throw std::invalid_argument("fit_tool_pose: a measured marker is not finite");
  MarkerFit fit;
  fit.X_NdiTool.matrix() = Eigen::umeyama(src, dst, false);  // rotation with det +1 (Umeyama's guard)
  double sum = 0.0;
  for (Eigen::Index i = 0; i < n; ++i) sum += (fit.X_NdiTool * src.col(i) - dst.col(i)).squaredNorm();
  fit.rms_error_mm = std::sqrt(sum / static_cast<double>(n));
  return fit;
}

std::optional<std::vector<Eigen::Vector3d>> rom_marker_positions(const std::vector<std::uint8_t>& rom) {
  if (rom.size() < kRomMarkerOffset + 12 * 3) return std::nullopt;
  const std::size_t count = rom[kRomMarkerCountOffset];
  if (count < 3 || count > kRomMaxMarkers || rom.size() < kRomMarkerOffset + 12 * count) return std::nullopt;
  std::vector<Eigen::Vector3d> m;
  for (std::size_t i = 0; i < count; ++i) {
    const std::size_t at = kRomMarkerOffset + 12 * i;
    const Eigen::Vector3d p(read_float_le(rom, at), read_float_le(rom, at + 4), read_float_le(rom, at + 8));
    if (!p.allFinite() || (p.array().abs() > 1000.0).any()) return std::nullopt;
    m.push_back(p);
  }
  if (!markers_define_a_pose(m)) return std::nullopt;
  return m;
}

std::vector<Eigen::Vector3d> default_marker_geometry() { return {{0, 0, 0}, {0, 50, 0}, {-35, 95, 0}, {40, 120, 0}}; }

std::mt19937_64 measurement_rng(std::uint64_t seed, int tool_index, std::uint32_t frame) {
  const std::uint64_t key = splitmix64(splitmix64(seed) ^ (static_cast<std::uint64_t>(static_cast<std::uint32_t>(tool_index)) << 32 | frame));
  return std::mt19937_64(key);
}

std::optional<MarkerFit> measure_tool(const MeasurementModel& model, const Eigen::Isometry3d& X_NdiTool_true,
                                      const std::vector<Eigen::Vector3d>& markers_Tool_mm, int tool_index, std::uint32_t frame,
                                      double ideal_rms_mm) {
  if (model.ideal) return MarkerFit{X_NdiTool_true, ideal_rms_mm};
  std::mt19937_64 rng = measurement_rng(model.seed, tool_index, frame);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  if (uniform(rng) < model.dropout_rate) return std::nullopt;
  std::normal_distribution<double> noise(0.0, model.marker_noise_rms_mm / std::sqrt(3.0));
  std::vector<Eigen::Vector3d> measured;
  measured.reserve(markers_Tool_mm.size());
  for (const auto& m : markers_Tool_mm) measured.push_back(X_NdiTool_true * m + Eigen::Vector3d(noise(rng), noise(rng), noise(rng)));
  return fit_tool_pose(markers_Tool_mm, measured);
}

}  // namespace arnav::hil
