#include "appliance/tools/decode.hpp"

#include <string>
#include <string_view>

#include "appliance/ndi/bx.hpp"
#include "appliance/ndi/error_codes.hpp"
#include "appliance/ndi/reply.hpp"
#include "appliance/ndi/transcript.hpp"

namespace arnav::tools {
namespace {

using nlohmann::json;
using namespace arnav::ndi;

std::string_view state_name(HandleState s) {
  switch (s) {
    case HandleState::Valid: return "valid";
    case HandleState::Missing: return "missing";
    case HandleState::Disabled: return "disabled";
    case HandleState::Unoccupied: return "unoccupied";
  }
  return "?";
}

json port_status_json(std::uint32_t s) {
  return {{"raw", s},
          {"occupied", (s & kPortOccupied) != 0},
          {"switch1", (s & kPortSwitch1) != 0},
          {"switch2", (s & kPortSwitch2) != 0},
          {"switch3", (s & kPortSwitch3) != 0},
          {"initialised", (s & kPortInitialised) != 0},
          {"enabled", (s & kPortEnabled) != 0},
          {"out_of_volume", (s & kPortOutOfVolume) != 0},
          {"partially_in_volume", (s & kPortPartiallyInVolume) != 0}};
}

json system_status_json(std::uint16_t s) {
  return {{"raw", s},
          {"comm_sync_error", (s & kSysCommSyncError) != 0},
          {"too_much_infrared", (s & kSysTooMuchInfrared) != 0},
          {"crc_error", (s & kSysCrcError) != 0},
          {"recoverable_comm_error", (s & kSysRecoverableCommError) != 0},
          {"hardware_failure", (s & kSysHardwareFailure) != 0},
          {"hardware_change", (s & kSysHardwareChange) != 0},
          {"port_occupied", (s & kSysPortOccupied) != 0},
          {"port_unoccupied", (s & kSysPortUnoccupied) != 0}};
}

json tracking_json(const TrackingReply& t) {
  json handles = json::array();
  for (std::size_t i = 0; i < t.count; ++i) {
    const HandleRecord& h = t.handles[i];
    json j = {{"handle", h.handle}, {"state", state_name(h.state)}};
    if (h.state == HandleState::Valid) {
      j["q_NdiTool_wxyz"] = h.q_NdiTool_wxyz;
      j["p_NdiTool_mm"] = h.p_NdiTool_mm;
      j["rms_error_mm"] = h.rms_error_mm;
    }
    if (h.has_status) {
      j["port_status"] = port_status_json(h.port_status);
      j["frame_number"] = h.frame_number;
    }
    handles.push_back(j);
  }
  return {{"handle_count", t.count}, {"handles", handles}, {"system_status", system_status_json(t.system_status)}};
}

json decode_ascii(std::string_view line) {
  json j;
  j["text"] = escape_bytes(line);
  std::string_view body;
  const ParseError crc = check_ascii_reply(line, body);
  j["crc_ok"] = crc == ParseError::None;
  if (crc != ParseError::None) {
    j["kind"] = "corrupt";
    j["error"] = to_string(crc);
    return j;
  }
  AsciiReply a;
  parse_ascii_reply(line, a);
  switch (a.kind) {
    case AsciiKind::Okay: j["kind"] = "okay"; return j;
    case AsciiKind::Reset: j["kind"] = "reset"; return j;
    case AsciiKind::Error: {
      const auto info = error_code_info(a.error_code);
      j["kind"] = "error";
      j["code"] = a.error_code;
      j["name"] = info.symbol;
      j["description"] = info.description;
      return j;
    }
    case AsciiKind::Warning:
      j["kind"] = "warning";
      if (a.has_code) j["code"] = a.error_code;
      return j;
    case AsciiKind::Data: break;
  }
  TrackingReply t;
  if (parse_tx(body, t) == ParseError::None) {
    j["kind"] = "tx";
    j.update(tracking_json(t));
    return j;
  }
  std::vector<PhsrEntry> phsr;
  if (body.size() > 2 && parse_phsr(body, phsr) == ParseError::None) {
    j["kind"] = "phsr";
    json hs = json::array();
    for (const auto& e : phsr) hs.push_back({{"handle", e.handle}, {"status", e.status}});
    j["handles"] = hs;
    return j;
  }
  PortHandleInfo info;
  if (parse_phinf_basic(body, info) == ParseError::None) {
    j["kind"] = "phinf";
    j["tool_type"] = info.tool_type;
    j["manufacturer"] = info.manufacturer;
    j["revision"] = info.revision;
    j["serial_number"] = info.serial_number;
    j["port_status"] = info.port_status;
    return j;
  }
  std::uint8_t handle = 0;
  if (parse_phrq(body, handle) == ParseError::None) {
    j["kind"] = "phrq";
    j["handle"] = handle;
    return j;
  }
  VersionInfo v;
  if (body.find('\n') != std::string_view::npos && parse_ver(body, v) == ParseError::None && !v.serial_number.empty()) {
    j["kind"] = "ver";
    j["firmware"] = v.firmware;
    j["serial_number"] = v.serial_number;
    j["lines"] = v.lines;
    return j;
  }
  j["kind"] = "data";
  j["body"] = escape_bytes(body);
  return j;
}

}  // namespace

std::vector<json> decode_replies(std::span<const std::uint8_t> bytes) {
  std::vector<json> out;
  std::size_t pos = 0;
  while (pos < bytes.size()) {
    json j;
    j["offset"] = pos;
    std::uint16_t length = 0;
    const auto rest = bytes.subspan(pos);
    if (rest.size() >= kBxHeaderBytes && check_bx_header(rest, length) == ParseError::None) {
      const std::size_t total = kBxHeaderBytes + length + 2u;
      if (rest.size() < total) {
        j["kind"] = "incomplete";
        j["length"] = rest.size();
        j["error"] = "BX frame cut off: header announces " + std::to_string(total) + " bytes";
        out.push_back(j);
        break;
      }
      TrackingReply t;
      const ParseError e = parse_bx(rest.first(total), t);
      j["length"] = total;
      j["kind"] = "bx";
      j["crc_ok"] = e != ParseError::BadCrc;
      if (e == ParseError::None) j.update(tracking_json(t));
      else j["error"] = to_string(e);
      out.push_back(j);
      pos += total;
      continue;
    }
    std::size_t cr = pos;
    while (cr < bytes.size() && bytes[cr] != '\r') ++cr;
    const std::string_view line(reinterpret_cast<const char*>(bytes.data() + pos), cr - pos);
    if (cr == bytes.size()) {
      j["kind"] = "incomplete";
      j["length"] = line.size();
      j["text"] = escape_bytes(line);
      j["error"] = "no CR at the end";
      out.push_back(j);
      break;
    }
    j["length"] = line.size() + 1;
    j.update(decode_ascii(line));
    out.push_back(j);
    pos = cr + 1;
  }
  return out;
}

}  // namespace arnav::tools
