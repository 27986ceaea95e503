#include "host/igtl/messages.hpp"

#include <cctype>
#include <cstring>

#include <igtlImageMessage.h>
#include <igtlPolyDataMessage.h>
#include <igtlStatusMessage.h>
#include <igtlTrackingDataMessage.h>
#include <igtlTransformMessage.h>
#include <igtl_util.h>

#include "host/igtl/wire.hpp"

namespace arnav::igtl {
namespace {

template <class MessagePointer>
void set_time(MessagePointer& msg, std::int64_t wall_us) {
  const std::uint64_t t = igtl_time_from_wall_us(wall_us);
  msg->SetTimeStamp(static_cast<unsigned int>(t >> 32), static_cast<unsigned int>(t & 0xffffffffu));
}

template <class MessagePointer>
Packet packed(MessagePointer& msg) {
  msg->Pack();
  const auto* bytes = static_cast<const std::uint8_t*>(msg->GetPackPointer());
  return std::make_shared<const std::vector<std::uint8_t>>(bytes, bytes + msg->GetPackSize());
}

void to_igtl_matrix(const Eigen::Isometry3d& X, ::igtl::Matrix4x4& m) {
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) m[r][c] = static_cast<float>(X.matrix()(r, c));
}

}  // namespace

std::string plus_frame_name(std::string_view arnav_name) {
  if (arnav_name == "Ref") return "Reference";
  if (arnav_name == "Ndi") return "Tracker";
  if (arnav_name == "Cam") return "Camera";
  std::string out;
  bool upper_next = true;
  for (const char ch : arnav_name) {
    if (ch == '_' || ch == '-' || ch == ' ' || ch == '.') {
      upper_next = true;
      continue;
    }
    if (!std::isalnum(static_cast<unsigned char>(ch))) continue;
    out.push_back(upper_next ? static_cast<char>(std::toupper(static_cast<unsigned char>(ch))) : ch);
    upper_next = false;
  }
  return out;
}

std::optional<std::string> transform_device_name(std::string_view child, std::string_view parent, std::string& why) {
  const std::string child_name = plus_frame_name(child);
  const std::string parent_name = plus_frame_name(parent);
  if (child_name.empty() || parent_name.empty()) {
    why = "frame name '" + std::string(child) + "' or '" + std::string(parent) + "' has no letters or digits";
    return std::nullopt;
  }
  std::string name = child_name + "To" + parent_name;
  if (name.size() > kMaxDeviceNameChars) {
    why = "transform name " + name + " has " + std::to_string(name.size()) +
          " characters, OpenIGTLink allows 20: give the tool a shorter name with --name TOOL=NAME";
    return std::nullopt;
  }
  return name;
}

std::uint64_t igtl_time_from_wall_us(std::int64_t wall_us) {
  if (wall_us < 0) wall_us = 0;
  const auto sec = static_cast<std::uint64_t>(wall_us / 1000000);
  const auto usec = static_cast<std::uint64_t>(wall_us % 1000000);
  const std::uint64_t frac = (usec << 32) / 1000000u;  // < 2^32
  return (sec << 32) | frac;
}

std::int64_t wall_us_from_igtl_time(std::uint64_t t) {
  const std::uint64_t sec = t >> 32;
  const std::uint64_t frac = t & 0xffffffffu;
  const std::uint64_t usec = (frac * 1000000u + (1ull << 31)) >> 32;  // rounded
  return static_cast<std::int64_t>(sec * 1000000u + usec);
}

Packet pack_transform(const std::string& device_name, const Eigen::Isometry3d& X_ParentChild_mm, std::int64_t wall_us) {
  auto msg = ::igtl::TransformMessage::New();
  msg->SetDeviceName(device_name.c_str());
  ::igtl::Matrix4x4 m;
  to_igtl_matrix(X_ParentChild_mm, m);
  msg->SetMatrix(m);
  set_time(msg, wall_us);
  return packed(msg);
}

Packet pack_tdata(const std::string& device_name, const std::vector<TrackedElement>& elements, std::int64_t wall_us) {
  auto msg = ::igtl::TrackingDataMessage::New();
  msg->SetDeviceName(device_name.c_str());
  for (const auto& e : elements) {
    auto element = ::igtl::TrackingDataElement::New();
    element->SetName(e.name.c_str());
    element->SetType(::igtl::TrackingDataElement::TYPE_6D);
    ::igtl::Matrix4x4 m;
    to_igtl_matrix(e.X_ParentChild_mm, m);
    element->SetMatrix(m);
    msg->AddTrackingDataElement(element);
  }
  set_time(msg, wall_us);
  return packed(msg);
}

Packet pack_status(const std::string& device_name, int code, const std::string& status_text, std::int64_t wall_us) {
  auto msg = ::igtl::StatusMessage::New();
  msg->SetDeviceName(device_name.c_str());
  msg->SetCode(code);
  msg->SetSubCode(0);
  msg->SetErrorName("");
  msg->SetStatusString(status_text.c_str());
  set_time(msg, wall_us);
  return packed(msg);
}

Packet pack_image_rgb(const std::string& device_name, int width, int height, const std::uint8_t* rgb, std::int64_t wall_us) {
  auto msg = ::igtl::ImageMessage::New();
  msg->SetDeviceName(device_name.c_str());
  msg->SetDimensions(width, height, 1);
  msg->SetSpacing(1.0f, 1.0f, 1.0f);
  msg->SetScalarTypeToUint8();
  msg->SetNumComponents(3);
  msg->SetEndian(::igtl::ImageMessage::ENDIAN_BIG);
  ::igtl::Matrix4x4 identity;
  ::igtl::IdentityMatrix(identity);
  msg->SetMatrix(identity);
  msg->AllocateScalars();
  std::memcpy(msg->GetScalarPointer(), rgb, static_cast<std::size_t>(width) * static_cast<std::size_t>(height) * 3u);
  set_time(msg, wall_us);
  return packed(msg);
}

Packet pack_polydata(const std::string& device_name, const std::vector<std::array<float, 3>>& points_mm,
                     const std::vector<std::array<std::uint32_t, 3>>& triangles, std::int64_t wall_us) {
  auto msg = ::igtl::PolyDataMessage::New();
  msg->SetDeviceName(device_name.c_str());
  auto points = ::igtl::PolyDataPointArray::New();
  points->SetNumberOfPoints(static_cast<int>(points_mm.size()));
  for (std::size_t i = 0; i < points_mm.size(); ++i)
    points->SetPoint(static_cast<unsigned int>(i), points_mm[i][0], points_mm[i][1], points_mm[i][2]);
  msg->SetPoints(points);
  auto polygons = ::igtl::PolyDataCellArray::New();
  for (auto t : triangles) polygons->AddCell(3, t.data());
  msg->SetPolygons(polygons);
  set_time(msg, wall_us);
  return packed(msg);
}

Packet pack_empty(const std::string& type, const std::string& device_name, std::int64_t wall_us) {
  Header h;
  h.version = 1;
  h.type = type;
  h.device_name = device_name;
  h.timestamp = igtl_time_from_wall_us(wall_us);
  h.body_size = 0;
  h.crc = body_crc({});
  auto bytes = std::make_shared<std::vector<std::uint8_t>>(kHeaderSize);
  write_header(h, bytes->data());
  return bytes;
}

Packet pack_rts(const std::string& type, const std::string& device_name, std::uint8_t status, std::int64_t wall_us) {
  Header h;
  h.version = 1;
  h.type = type;
  h.device_name = device_name;
  h.timestamp = igtl_time_from_wall_us(wall_us);
  h.body_size = 1;
  h.crc = body_crc(std::span<const std::uint8_t>(&status, 1));
  auto bytes = std::make_shared<std::vector<std::uint8_t>>(kHeaderSize + 1);
  write_header(h, bytes->data());
  (*bytes)[kHeaderSize] = status;
  return bytes;
}

}  // namespace arnav::igtl
