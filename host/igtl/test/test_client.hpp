#pragma once
// Test support (never linked by arnav-igtl): an OpenIGTLink client on a raw socket that
// frames what it receives with igtl::StreamReader (every type kept) and unpacks bodies with
// libopenigtlink (CRC checked), plus requests as 3D Slicer and the examples send them.
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "arnav/surface_mesh_t.hpp"
#include "host/igtl/wire.hpp"

namespace arnav::igtl::test {

class TestClient {
 public:
  // Connects to 127.0.0.1:port; on failure connected() is false and why() says why.
  explicit TestClient(int port);
  ~TestClient();
  TestClient(const TestClient&) = delete;
  TestClient& operator=(const TestClient&) = delete;

  bool connected() const { return fd_ >= 0; }
  const std::string& why() const { return why_; }
  bool send(const std::vector<std::uint8_t>& bytes);
  // Receives until `count` messages arrived in total since the last take(), the server
  // closed, or timeout_s passed; returns the messages received so far (and keeps them).
  const std::vector<Message>& receive_until(std::size_t count, double timeout_s);
  std::vector<Message> take();
  bool closed_by_server() const { return closed_; }
  // Closes with a TCP reset, as when the process is killed.
  void reset();

 private:
  int fd_ = -1;
  std::string why_;
  bool closed_ = false;
  StreamReader reader_;
  std::vector<Message> received_;
  std::vector<std::uint8_t> buffer_ = std::vector<std::uint8_t>(256 * 1024);
};

std::vector<std::uint8_t> raw_header_bytes(const Header& header);
// A header-only request (STP_TDATA, GET_STATUS) or STT_TDATA (resolution ms + coordinate name).
std::vector<std::uint8_t> request(const std::string& type, std::uint16_t version = 1);
// A header-only request with this device name (GET_POLYDATA "Organ"; "" asks for any).
std::vector<std::uint8_t> named_request(const std::string& type, const std::string& device_name, std::uint16_t version = 1);
std::vector<std::uint8_t> start_tdata_request(int resolution_ms);
// What 3D Slicer's OpenIGTLinkIF sends on connect: a header-version-2 STATUS with an
// extended header and metadata.
std::vector<std::uint8_t> slicer_v2_status();

struct Unpacked {
  bool crc_ok = false;
  std::string device_name;
  std::int64_t wall_us = 0;
  Eigen::Matrix4d matrix = Eigen::Matrix4d::Zero();          // TRANSFORM
  std::vector<std::pair<std::string, Eigen::Matrix4d>> tdata; // TDATA elements
  int status_code = 0;                                         // STATUS; RTS_* (0 success)
  int width = 0, height = 0, components = 0, scalar_type = 0;  // IMAGE
  std::vector<std::uint8_t> pixels;                            // IMAGE
  bool empty_body = false;                                     // POLYDATA: the "not available" answer
  std::vector<std::array<float, 3>> points_mm;                 // POLYDATA
  std::vector<std::vector<std::uint32_t>> polygons;            // POLYDATA
  std::size_t other_cells = 0;                                 // POLYDATA vertices, lines, strips
};
// Unpacks a TRANSFORM, TDATA, STATUS, IMAGE or POLYDATA with libopenigtlink, an RTS_* by hand
// (CRC checked).
Unpacked unpack(const Message& message);

// A closed surface as arnav-host publishes it (ARNAV_SURFACE_<name>, frame "Ref"): a UV
// sphere of radius 60 mm, `rings` x `segments` (2 + (rings - 1) * segments vertices,
// 2 * (rings - 1) * segments triangles), its radius rippled by `phase` (a deforming organ).
surface_mesh_t sphere_surface(const std::string& name, int rings, int segments, double phase, std::int64_t wall_us);

}  // namespace arnav::igtl::test
