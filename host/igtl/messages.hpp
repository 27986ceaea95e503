#pragma once
// OpenIGTLink messages arnav-igtl sends, packed with Debian's libopenigtlink (docs/igtl.md),
// and the PLUS naming of transforms. Every message carries the UTC time of what it shows.
#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Geometry>

namespace arnav::igtl {

// Bytes of one packed message (header + body), shared by every client that sends it.
using Packet = std::shared_ptr<const std::vector<std::uint8_t>>;

inline constexpr std::size_t kMaxDeviceNameChars = 20;

// "pointer" -> "Pointer", "stylus_tip" -> "StylusTip"; the ARNav frames keep PLUS's words:
// "Ref" -> "Reference", "Ndi" -> "Tracker", "Cam" -> "Camera".
std::string plus_frame_name(std::string_view arnav_name);
// PLUS device name of X_ParentChild: "<Child>To<Parent>" (e.g. "PointerToReference").
// nullopt with `why` when it is longer than 20 characters (the OpenIGTLink device name field).
std::optional<std::string> transform_device_name(std::string_view child, std::string_view parent, std::string& why);

// OpenIGTLink time (32.32 fixed point seconds since the Unix epoch) of a wall-clock time.
std::uint64_t igtl_time_from_wall_us(std::int64_t wall_us);
std::int64_t wall_us_from_igtl_time(std::uint64_t igtl_time);

Packet pack_transform(const std::string& device_name, const Eigen::Isometry3d& X_ParentChild_mm, std::int64_t wall_us);

struct TrackedElement {
  std::string name;                 // device name, <= 20 characters
  Eigen::Isometry3d X_ParentChild_mm;
};
Packet pack_tdata(const std::string& device_name, const std::vector<TrackedElement>& elements, std::int64_t wall_us);

// STATUS: code 1 is STATUS_OK (the keep-alive).
Packet pack_status(const std::string& device_name, int code, const std::string& status_text, std::int64_t wall_us);

// IMAGE of 8-bit RGB pixels (row-major, 3 bytes per pixel), spacing 1, identity matrix.
Packet pack_image_rgb(const std::string& device_name, int width, int height, const std::uint8_t* rgb, std::int64_t wall_us);

// POLYDATA of a triangulated surface: points (float32, the mesh's frame, mm) and one
// 3-point polygon per triangle (indices into points, checked by the caller); no attributes.
Packet pack_polydata(const std::string& device_name, const std::vector<std::array<float, 3>>& points_mm,
                     const std::vector<std::array<std::uint32_t, 3>>& triangles, std::int64_t wall_us);

// A message of `type` with an empty body (body size 0): OpenIGTLink's answer to a GET_<type>
// query for data that is not available (the protocol's "Query Message" section).
Packet pack_empty(const std::string& type, const std::string& device_name, std::int64_t wall_us);
// The answer to a start or stop request (e.g. RTS_POLYDATA): a one-byte body, the status
// (0 success, 1 error; OpenIGTLink v2).
Packet pack_rts(const std::string& type, const std::string& device_name, std::uint8_t status, std::int64_t wall_us);

}  // namespace arnav::igtl
