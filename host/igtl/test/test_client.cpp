#include "host/igtl/test/test_client.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>

#include <igtlImageMessage.h>
#include <igtlMessageHeader.h>
#include <igtlPolyDataMessage.h>
#include <igtlStatusMessage.h>
#include <igtlTrackingDataMessage.h>
#include <igtlTransformMessage.h>

#include "host/igtl/messages.hpp"

namespace arnav::igtl::test {

TestClient::TestClient(int port) : reader_({"TRANSFORM", "TDATA", "STATUS", "IMAGE", "POLYDATA", "RTS_POLYDATA"}, 1ull << 28, 1ull << 28) {
  fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<std::uint16_t>(port));
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (fd_ < 0 || ::connect(fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0) {
    why_ = "cannot connect to 127.0.0.1:" + std::to_string(port) + ": " + std::strerror(errno);
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }
}

TestClient::~TestClient() {
  if (fd_ >= 0) ::close(fd_);
}

bool TestClient::send(const std::vector<std::uint8_t>& bytes) {
  return fd_ >= 0 && ::send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(bytes.size());
}

const std::vector<Message>& TestClient::receive_until(std::size_t count, double timeout_s) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  std::vector<std::uint8_t>& buffer = buffer_;
  while (fd_ >= 0 && !closed_ && received_.size() < count && std::chrono::steady_clock::now() < end) {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, 20) <= 0) continue;
    const ssize_t n = ::recv(fd_, buffer.data(), buffer.size(), 0);
    if (n <= 0) {
      closed_ = true;
      break;
    }
    reader_.feed(std::span<const std::uint8_t>(buffer.data(), static_cast<std::size_t>(n)));
    while (auto m = reader_.next()) received_.push_back(std::move(*m));
    if (reader_.failed()) closed_ = true;
  }
  return received_;
}

std::vector<Message> TestClient::take() {
  std::vector<Message> out;
  out.swap(received_);
  return out;
}

void TestClient::reset() {
  if (fd_ < 0) return;
  linger l{1, 0};
  ::setsockopt(fd_, SOL_SOCKET, SO_LINGER, &l, sizeof l);
  ::close(fd_);
  fd_ = -1;
}

std::vector<std::uint8_t> raw_header_bytes(const Header& header) {
  std::vector<std::uint8_t> out(kHeaderSize);
  write_header(header, out.data());
  return out;
}

namespace {
std::vector<std::uint8_t> with_body(Header h, const std::vector<std::uint8_t>& body) {
  h.body_size = body.size();
  h.crc = body_crc(body);
  h.timestamp = igtl_time_from_wall_us(1'700'000'000'000'000);
  auto out = raw_header_bytes(h);
  out.insert(out.end(), body.begin(), body.end());
  return out;
}
void put_be(std::vector<std::uint8_t>& v, std::uint64_t x, int bytes) {
  for (int i = bytes - 1; i >= 0; --i) v.push_back(static_cast<std::uint8_t>((x >> (8 * i)) & 0xffu));
}
}  // namespace

std::vector<std::uint8_t> request(const std::string& type, std::uint16_t version) { return named_request(type, "TestClient", version); }

std::vector<std::uint8_t> named_request(const std::string& type, const std::string& device_name, std::uint16_t version) {
  Header h;
  h.version = version;
  h.type = type;
  h.device_name = device_name;
  std::vector<std::uint8_t> body;
  if (version >= 2) {  // extended header only
    put_be(body, 12, 2);
    put_be(body, 0, 2);
    put_be(body, 0, 4);
    put_be(body, 1, 4);
  }
  return with_body(h, body);
}

std::vector<std::uint8_t> start_tdata_request(int resolution_ms) {
  Header h{1, "STT_TDATA", "TestClient", 0, 0, 0};
  std::vector<std::uint8_t> body(4 + 32, 0);  // resolution (ms), coordinate name char[32]
  for (int i = 0; i < 4; ++i) body[static_cast<std::size_t>(i)] = static_cast<std::uint8_t>((static_cast<std::uint32_t>(resolution_ms) >> (8 * (3 - i))) & 0xffu);
  const std::string coordinate = "Patient";
  std::copy(coordinate.begin(), coordinate.end(), body.begin() + 4);
  return with_body(h, body);
}

std::vector<std::uint8_t> slicer_v2_status() {
  Header h{2, "STATUS", "SlicerConnector", 0, 0, 0};
  std::vector<std::uint8_t> content;
  put_be(content, 1, 2);  // STATUS_OK
  put_be(content, 0, 8);  // subcode
  content.resize(content.size() + 20 + 1, 0);  // empty error name char[20], empty status string
  const std::string key = "Connected", value = "true";
  std::vector<std::uint8_t> meta_header;
  put_be(meta_header, 1, 2);   // one entry
  put_be(meta_header, key.size(), 2);
  put_be(meta_header, 3, 2);   // US-ASCII
  put_be(meta_header, value.size(), 4);
  std::vector<std::uint8_t> body;
  put_be(body, 12, 2);
  put_be(body, meta_header.size(), 2);
  put_be(body, key.size() + value.size(), 4);
  put_be(body, 7, 4);  // message id
  body.insert(body.end(), content.begin(), content.end());
  body.insert(body.end(), meta_header.begin(), meta_header.end());
  body.insert(body.end(), key.begin(), key.end());
  body.insert(body.end(), value.begin(), value.end());
  return with_body(h, body);
}

namespace {
template <class MessagePointer>
bool unpack_into(MessagePointer& msg, const Message& m) {
  auto header = ::igtl::MessageHeader::New();
  header->InitPack();
  const auto bytes = raw_header_bytes(m.header);
  std::memcpy(header->GetPackPointer(), bytes.data(), kHeaderSize);
  header->Unpack();
  msg->SetMessageHeader(header);
  msg->AllocatePack();
  if (static_cast<std::size_t>(msg->GetPackBodySize()) != m.body.size()) return false;
  std::memcpy(msg->GetPackBodyPointer(), m.body.data(), m.body.size());
  return (msg->Unpack(1) & ::igtl::MessageHeader::UNPACK_BODY) != 0;
}
Eigen::Matrix4d to_eigen(::igtl::Matrix4x4& m) {
  Eigen::Matrix4d out;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) out(r, c) = m[r][c];
  return out;
}
}  // namespace

Unpacked unpack(const Message& m) {
  Unpacked u;
  u.device_name = m.header.device_name;
  u.wall_us = wall_us_from_igtl_time(m.header.timestamp);
  const std::string& type = m.header.type;
  if (type == "TRANSFORM") {
    auto msg = ::igtl::TransformMessage::New();
    if ((u.crc_ok = unpack_into(msg, m))) {
      ::igtl::Matrix4x4 mat;
      msg->GetMatrix(mat);
      u.matrix = to_eigen(mat);
    }
  } else if (type == "TDATA") {
    auto msg = ::igtl::TrackingDataMessage::New();
    if ((u.crc_ok = unpack_into(msg, m))) {
      for (int i = 0; i < msg->GetNumberOfTrackingDataElements(); ++i) {
        ::igtl::TrackingDataElement::Pointer e;
        msg->GetTrackingDataElement(i, e);
        ::igtl::Matrix4x4 mat;
        e->GetMatrix(mat);
        u.tdata.emplace_back(e->GetName(), to_eigen(mat));
      }
    }
  } else if (type == "STATUS") {
    auto msg = ::igtl::StatusMessage::New();
    if ((u.crc_ok = unpack_into(msg, m))) u.status_code = msg->GetCode();
  } else if (type == "IMAGE") {
    auto msg = ::igtl::ImageMessage::New();
    if ((u.crc_ok = unpack_into(msg, m))) {
      int size[3];
      msg->GetDimensions(size);
      u.width = size[0];
      u.height = size[1];
      u.components = msg->GetNumComponents();
      u.scalar_type = msg->GetScalarType();
      const auto* p = static_cast<const std::uint8_t*>(msg->GetScalarPointer());
      u.pixels.assign(p, p + static_cast<std::size_t>(msg->GetImageSize()));
    }
  } else if (type.rfind("RTS_", 0) == 0) {  // one status byte (0 success)
    u.crc_ok = m.body_kept && body_crc(m.body) == m.header.crc;
    if (u.crc_ok && m.body.size() == 1) u.status_code = m.body[0];
    else u.crc_ok = false;
  } else if (type == "POLYDATA") {
    u.empty_body = m.header.body_size == 0;
    auto msg = ::igtl::PolyDataMessage::New();
    if (u.empty_body) {
      u.crc_ok = m.header.crc == body_crc({});
    } else if ((u.crc_ok = unpack_into(msg, m))) {
      if (auto* points = msg->GetPoints())
        for (int i = 0; i < points->GetNumberOfPoints(); ++i) {
          std::array<float, 3> p{};
          points->GetPoint(static_cast<unsigned int>(i), p.data());
          u.points_mm.push_back(p);
        }
      if (auto* polygons = msg->GetPolygons())
        for (unsigned int i = 0; i < polygons->GetNumberOfCells(); ++i) {
          std::vector<std::uint32_t> cell(polygons->GetCellSize(i));
          polygons->GetCell(i, cell.data());
          u.polygons.push_back(std::move(cell));
        }
      u.other_cells = (msg->GetVertices() ? msg->GetVertices()->GetNumberOfCells() : 0) +
                      (msg->GetLines() ? msg->GetLines()->GetNumberOfCells() : 0) +
                      (msg->GetTriangleStrips() ? msg->GetTriangleStrips()->GetNumberOfCells() : 0);
    }
  }
  return u;
}

surface_mesh_t sphere_surface(const std::string& name, int rings, int segments, double phase, std::int64_t wall_us) {
  surface_mesh_t m;
  m.name = name;
  m.frame_name = "Ref";
  m.model_time_us = 1000;
  m.model_step = 1;
  m.model_step_wall_us = wall_us;
  m.publish_time_wall_us = wall_us + 100;
  m.sequence = 1;
  const auto vertex = [&](double theta, double phi) {
    const double r = 60.0 + 3.0 * std::sin(3.0 * phi + phase) * std::sin(theta);
    m.positions_mm.push_back({static_cast<float>(r * std::sin(theta) * std::cos(phi)), static_cast<float>(r * std::sin(theta) * std::sin(phi)),
                              static_cast<float>(-1400.0 + r * std::cos(theta))});
  };
  const double pi = std::acos(-1.0);
  vertex(0.0, 0.0);  // north pole: 0
  for (int i = 1; i < rings; ++i)
    for (int j = 0; j < segments; ++j) vertex(pi * i / rings, 2.0 * pi * j / segments);
  vertex(pi, 0.0);  // south pole: last
  const int south = static_cast<int>(m.positions_mm.size()) - 1;
  const auto at = [&](int ring, int seg) { return 1 + (ring - 1) * segments + (seg % segments); };
  for (int j = 0; j < segments; ++j) {
    m.triangles.push_back({0, at(1, j), at(1, j + 1)});
    m.triangles.push_back({south, at(rings - 1, j + 1), at(rings - 1, j)});
  }
  for (int i = 1; i + 1 < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      m.triangles.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      m.triangles.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  m.num_vertices = static_cast<std::int32_t>(m.positions_mm.size());
  m.num_triangles = static_cast<std::int32_t>(m.triangles.size());
  m.rgba[0] = 0.95f;
  m.rgba[1] = 0.75f;
  m.rgba[2] = 0.65f;
  m.rgba[3] = 0.25f;
  return m;
}

}  // namespace arnav::igtl::test
