#pragma once
// Device-side encoders of NDI Combined API replies (only the simulated Polaris encodes;
// the appliance's parsers live in appliance/ndi). Text replies end with 4 uppercase hex
// CRC-16/ARC digits and CR; BX replies are little-endian binary frames (see
// ../shared/docs/ndi-capi.md). Poses are X_NdiTool: positions in mm, quaternion w first.
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Geometry>

namespace arnav::hil {

using Bytes = std::vector<std::uint8_t>;

// Port status bits (ndi-capi.md "Port status bits").
inline constexpr std::uint32_t kPortOccupied = 0x01;
inline constexpr std::uint32_t kPortInitialised = 0x10;
inline constexpr std::uint32_t kPortEnabled = 0x20;
inline constexpr std::uint32_t kPortOutOfVolume = 0x40;
inline constexpr std::uint32_t kPortPartiallyInVolume = 0x80;

// Reply options of TX/BX understood by the simulator.
inline constexpr std::uint16_t kReplyTransforms = 0x0001;
inline constexpr std::uint16_t kReplyOutOfVolume = 0x0800;

// One handle in a TX/BX reply.
struct HandleReport {
  enum class Kind { kValid, kMissing, kDisabled };
  std::uint8_t handle = 0;
  Kind kind = Kind::kMissing;
  Eigen::Quaterniond q_NdiTool = Eigen::Quaterniond::Identity();  // unit, w >= 0
  Eigen::Vector3d p_NdiTool_mm = Eigen::Vector3d::Zero();
  double rms_error_mm = 0.0;
  std::uint32_t port_status = 0;
  std::uint32_t frame_number = 0;
};

// "<text><CRC hex>\r"
Bytes text_reply(std::string_view text);
Bytes okay_reply();
Bytes error_reply(std::uint8_t code);
Bytes reset_reply();

// TX reply with option 0x0001 data (plus out-of-volume tools if the caller includes them).
Bytes tx_reply(const std::vector<HandleReport>& handles, std::uint16_t system_status);
// BX reply with option 0x0001 data.
Bytes bx_reply(const std::vector<HandleReport>& handles, std::uint16_t system_status);

// Fixed-width fields of TX: sign + digits, value scaled (e.g. 1e4 for quaternions).
std::string signed_field(double value, double scale, int digits);
std::string hex_field(std::uint32_t value, int digits);

}  // namespace arnav::hil
