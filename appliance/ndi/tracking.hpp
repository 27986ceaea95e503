#pragma once
// Decoded tracking data of one BX or TX reply (one device frame, all port handles).
// Plain fixed-size values so the per-frame hot path allocates nothing.
#include <array>
#include <cstdint>

#include <Eigen/Geometry>

namespace arnav::ndi {

// Port status bits (both TX and BX).
inline constexpr std::uint32_t kPortOccupied = 0x01;
inline constexpr std::uint32_t kPortSwitch1 = 0x02;
inline constexpr std::uint32_t kPortSwitch2 = 0x04;
inline constexpr std::uint32_t kPortSwitch3 = 0x08;
inline constexpr std::uint32_t kPortInitialised = 0x10;
inline constexpr std::uint32_t kPortEnabled = 0x20;
inline constexpr std::uint32_t kPortOutOfVolume = 0x40;
inline constexpr std::uint32_t kPortPartiallyInVolume = 0x80;

// System status bits (trailing word of TX and BX).
inline constexpr std::uint16_t kSysCommSyncError = 0x01;
inline constexpr std::uint16_t kSysTooMuchInfrared = 0x02;
inline constexpr std::uint16_t kSysCrcError = 0x04;
inline constexpr std::uint16_t kSysRecoverableCommError = 0x08;
inline constexpr std::uint16_t kSysHardwareFailure = 0x10;
inline constexpr std::uint16_t kSysHardwareChange = 0x20;
inline constexpr std::uint16_t kSysPortOccupied = 0x40;
inline constexpr std::uint16_t kSysPortUnoccupied = 0x80;

// More handles than any Polaris reports in one frame; a reply claiming more is rejected.
inline constexpr std::size_t kMaxHandles = 32;

enum class HandleState : std::uint8_t { Valid, Missing, Disabled, Unoccupied };

struct HandleRecord {
  std::uint8_t handle = 0;
  HandleState state = HandleState::Disabled;
  // Valid only when state == Valid. NDI quaternion order: q0 (w) first.
  std::array<double, 4> q_NdiTool_wxyz{1.0, 0.0, 0.0, 0.0};
  std::array<double, 3> p_NdiTool_mm{0.0, 0.0, 0.0};
  double rms_error_mm = 0.0;
  // Present for Valid and Missing (and, on some firmware, in TX for Disabled).
  bool has_status = false;
  std::uint32_t port_status = 0;
  std::uint32_t frame_number = 0;

  bool out_of_volume() const { return (port_status & kPortOutOfVolume) != 0; }
  bool partially_in_volume() const { return (port_status & kPortPartiallyInVolume) != 0; }
};

struct TrackingReply {
  std::size_t count = 0;
  std::array<HandleRecord, kMaxHandles> handles{};
  std::uint16_t system_status = 0;
  // BX2 (GBF) replies carry the frame number and the device's timestamp once per frame,
  // also when no tool has new data; BX/TX leave these false.
  bool has_frame = false;
  std::uint32_t frame = 0;
  bool has_device_time = false;
  std::int64_t device_time_ns = 0;  // device clock: seconds * 1e9 + nanoseconds of the frame

  // The reply's frame number (BX2), else that of the first handle that carries one; 0
  // when none does.
  std::uint32_t frame_number() const;
  const HandleRecord* find(std::uint8_t handle) const;
};

// Pose of the tool in the tracker frame (maps tool coordinates into Ndi coordinates).
// Only meaningful for Valid records; the quaternion is normalised.
Eigen::Isometry3d X_NdiTool(const HandleRecord& record);

}  // namespace arnav::ndi
