#pragma once
// Test support (never linked by arnav-igtl): an OpenIGTLink client on a raw socket that
// frames what it receives with igtl::StreamReader (every type kept) and unpacks bodies with
// libopenigtlink (CRC checked), plus requests as 3D Slicer and the examples send them.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

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
  int status_code = 0;                                         // STATUS
  int width = 0, height = 0, components = 0, scalar_type = 0;  // IMAGE
  std::vector<std::uint8_t> pixels;                            // IMAGE
};
// Unpacks a TRANSFORM, TDATA, STATUS or IMAGE with libopenigtlink (CRC checked).
Unpacked unpack(const Message& message);

}  // namespace arnav::igtl::test
