#include "hil_tests/polaris_sim/device_model.hpp"

#include <algorithm>
#include <cmath>

#include "appliance/ndi/bx2.hpp"
#include "appliance/ndi/command.hpp"

namespace arnav::hil {
namespace {

// Error codes (ndi-capi.md "Replies and errors").
constexpr std::uint8_t kInvalidCommand = 0x01;
constexpr std::uint8_t kBadCrc = 0x04;
constexpr std::uint8_t kCommFailed = 0x06;
constexpr std::uint8_t kBadParameterCount = 0x07;
constexpr std::uint8_t kInvalidHandle = 0x08;
constexpr std::uint8_t kInvalidMode = 0x0C;
constexpr std::uint8_t kNoTool = 0x0D;
constexpr std::uint8_t kNotInitialised = 0x0E;
constexpr std::uint8_t kNotEnabled = 0x0F;
constexpr std::uint8_t kSystemNotInitialised = 0x10;
constexpr std::uint8_t kOutOfRange = 0x23;
constexpr std::uint8_t kTooManyTools = 0x28;
constexpr std::uint8_t kToolDefinitionError = 0x41;
constexpr std::size_t kMaxInputLine = 1024;   // longer garbage is dropped
constexpr std::size_t kRomSize = 1024;
constexpr std::uint8_t kFirstHandle = 0x0A;
constexpr int kMaxPassiveHandles = 12;

bool is_hex(std::string_view s) {  // whole field, any case
  return !s.empty() && s.find_first_not_of("0123456789ABCDEFabcdef") == std::string_view::npos;
}

unsigned parse_hex(std::string_view s) { return static_cast<unsigned>(std::stoul(std::string(s), nullptr, 16)); }

PolarisModel::Reply reply(Bytes bytes) { return PolarisModel::Reply{std::move(bytes), {}, 0}; }

}  // namespace

PolarisModel::PolarisModel(Scenario scenario) : scenario_(std::move(scenario)) {}

bool PolarisModel::knows_tool(const std::string& tool) const {
  return std::any_of(scenario_.tools.begin(), scenario_.tools.end(), [&](const SimTool& t) { return t.name == tool; });
}

std::uint32_t PolarisModel::frame_at(double now_s) const {
  const double elapsed = std::max(0.0, now_s - boot_s_);
  return scenario_.first_frame + static_cast<std::uint32_t>(std::floor(elapsed * scenario_.frame_rate_hz));
}

double PolarisModel::motion_time_s(std::uint32_t frame) const {
  const double t_s = static_cast<double>(frame) / scenario_.frame_rate_hz;
  if (!scenario_.epoch_mono_us) return t_s;
  // Motions subtract first_frame / rate (the boot): add back the boot's world time.
  return t_s + clock_origin_mono_s_ + boot_s_ - static_cast<double>(*scenario_.epoch_mono_us) * 1e-6;
}

Bytes PolarisModel::reset(double now_s) {
  input_.clear();
  baud_ = 9600;
  initialised_ = false;
  tracking_ = false;
  boot_s_ = now_s;
  ports_.clear();
  return reset_reply();
}

std::vector<PolarisModel::Reply> PolarisModel::receive(std::span<const std::uint8_t> bytes, double now_s) {
  std::vector<Reply> out;
  for (std::uint8_t b : bytes) {
    if (b == '\r') {
      std::string line;
      line.swap(input_);
      if (line.empty()) continue;
      Reply r = execute(line, now_s);
      r.command = line;
      out.push_back(std::move(r));
    } else if (input_.size() < kMaxInputLine) {
      input_.push_back(static_cast<char>(b));
    }
  }
  return out;
}

int PolarisModel::identify_tool(const std::vector<std::uint8_t>& rom, std::uint16_t bytes_written) const {
  // The device recognises a tool by its definition. A scenario tool is on one handle at a
  // time; tools without a ROM file take the remaining loaded ROMs in order (so a bench
  // may run more tools than there are distinct ROM files).
  const auto taken = [&](std::size_t i) {
    return std::any_of(ports_.begin(), ports_.end(), [&](const auto& kv) { return kv.second.tool_index == static_cast<int>(i); });
  };
  for (std::size_t i = 0; i < scenario_.tools.size(); ++i) {
    const auto& want = scenario_.tools[i].rom;
    if (want.empty() || want.size() > bytes_written || taken(i)) continue;
    if (std::equal(want.begin(), want.end(), rom.begin()) &&
        std::all_of(rom.begin() + static_cast<std::ptrdiff_t>(want.size()), rom.begin() + bytes_written, [](std::uint8_t b) { return b == 0; }))
      return static_cast<int>(i);
  }
  for (std::size_t i = 0; i < scenario_.tools.size(); ++i)
    if (scenario_.tools[i].rom.empty() && !taken(i)) return static_cast<int>(i);
  return -1;
}

PolarisModel::Reply PolarisModel::execute(const std::string& raw, double now_s) {
  // "CMD:params" + CRC, or the space form "CMD params" without CRC.
  const auto decoded = ndi::decode_command(raw);
  if (!decoded) return reply(error_reply(kInvalidCommand));
  if (decoded->has_crc && !decoded->crc_ok) return reply(error_reply(kBadCrc));
  const std::string name(decoded->name);
  const std::string params(decoded->params);

  if (name == "INIT") {
    initialised_ = true;
    return reply(okay_reply());
  }
  if (name == "COMM") {
    if (params.size() != 5 || params[1] != '0' || params[2] != '0' || params[3] != '0' || (params[4] != '0' && params[4] != '1'))
      return reply(error_reply(params.size() == 5 ? kCommFailed : kBadParameterCount));
    const auto baud = ndi::baud_from_code(params[0]);
    if (!baud) return reply(error_reply(kCommFailed));
    Reply r = reply(okay_reply());
    r.baud_after = *baud;
    return r;
  }
  if (name == "VER") {
    if (params == "0")
      return reply(text_reply("Polaris Simulated Control Firmware\nNDI S/N: " + scenario_.serial_number +
                              "\nFreeze Tag: ARNAV HIL SIM Rev 001\n(C) ARNav HIL bench\n"));
    if (params == "4") return reply(text_reply("Polaris Simulated Enhanced Firmware\nCombined API rev 003\n"));
    if (params == "5") return reply(text_reply("031.001"));
    return reply(error_reply(kOutOfRange));
  }
  if (name == "APIREV") return reply(text_reply(api_revision_));
  if (name == "BEEP") return reply(text_reply(params.size() == 1 && params[0] >= '1' && params[0] <= '9' ? "1" : "0"));
  if (!initialised_) return reply(error_reply(kSystemNotInitialised));

  // Handle commands take the two-hex-digit handle first.
  const auto find_port = [&](std::uint8_t& handle) -> Port* {
    if (params.size() < 2 || !is_hex(std::string_view(params).substr(0, 2))) return nullptr;
    handle = static_cast<std::uint8_t>(parse_hex(std::string_view(params).substr(0, 2)));
    auto it = ports_.find(handle);
    return it == ports_.end() ? nullptr : &it->second;
  };
  std::uint8_t handle = 0;

  if (name == "PHSR") {
    const std::string which = params.empty() ? "00" : params;
    if (which.size() != 2 || !is_hex(which)) return reply(error_reply(kOutOfRange));
    const unsigned mode = parse_hex(which);
    std::string s;
    int n = 0;
    for (const auto& [h, p] : ports_) {
      const bool pick = mode == 0 || (mode == 2 && !p.initialised) || (mode == 3 && p.initialised && !p.enabled) ||
                        (mode == 4 && p.enabled);
      if (!pick) continue;
      ++n;
      const std::uint32_t status = (p.tool_index >= 0 ? ndi::kPortOccupied : 0) | (p.initialised ? ndi::kPortInitialised : 0) |
                                    (p.enabled ? ndi::kPortEnabled : 0);
      s += hex_field(h, 2) + hex_field(status, 3);
    }
    return reply(text_reply(hex_field(static_cast<std::uint32_t>(n), 2) + s));
  }
  if (name == "PHRQ") {
    if (tracking_) return reply(error_reply(kInvalidMode));
    if (params.size() != 14) return reply(error_reply(kBadParameterCount));
    if (static_cast<int>(ports_.size()) >= kMaxPassiveHandles) return reply(error_reply(kTooManyTools));
    std::uint8_t h = kFirstHandle;
    while (ports_.count(h)) ++h;
    ports_[h].rom.assign(kRomSize, 0);
    return reply(text_reply(hex_field(h, 2)));
  }
  if (name == "PHF") {
    Port* p = find_port(handle);
    if (!p) return reply(error_reply(kInvalidHandle));
    if (tracking_ && p->enabled) return reply(error_reply(kInvalidMode));
    ports_.erase(handle);
    return reply(okay_reply());
  }
  if (name == "PVWR") {
    if (tracking_) return reply(error_reply(kInvalidMode));
    if (params.size() != 2 + 4 + 128) return reply(error_reply(kBadParameterCount));
    Port* p = find_port(handle);
    if (!p) return reply(error_reply(kInvalidHandle));
    const std::string_view addr_hex = std::string_view(params).substr(2, 4);
    const std::string_view data_hex = std::string_view(params).substr(6);
    if (!is_hex(addr_hex) || !is_hex(data_hex)) return reply(error_reply(kOutOfRange));
    const unsigned addr = parse_hex(addr_hex);
    if (addr % 64 != 0 || addr + 64 > kRomSize) return reply(error_reply(kOutOfRange));
    for (unsigned i = 0; i < 64; ++i) p->rom[addr + i] = static_cast<std::uint8_t>(parse_hex(data_hex.substr(2 * i, 2)));
    p->rom_bytes_written = static_cast<std::uint16_t>(std::max<unsigned>(p->rom_bytes_written, addr + 64));
    p->initialised = false;
    p->tool_index = -1;
    return reply(okay_reply());
  }
  if (name == "PINIT") {
    if (tracking_) return reply(error_reply(kInvalidMode));
    Port* p = find_port(handle);
    if (!p) return reply(error_reply(kInvalidHandle));
    if (p->rom_bytes_written == 0) return reply(error_reply(kNoTool));
    if (!(p->rom[0] == 'N' && p->rom[1] == 'D' && p->rom[2] == 'I' && p->rom[3] == 0)) return reply(error_reply(kToolDefinitionError));
    p->tool_index = -1;  // re-initialising a handle frees its tool first
    p->tool_index = identify_tool(p->rom, p->rom_bytes_written);
    p->initialised = true;
    return reply(okay_reply());
  }
  if (name == "PENA") {
    if (tracking_) return reply(error_reply(kInvalidMode));
    Port* p = find_port(handle);
    if (!p) return reply(error_reply(kInvalidHandle));
    if (params.size() != 3 || (params[2] != 'S' && params[2] != 'D' && params[2] != 'B')) return reply(error_reply(kOutOfRange));
    if (!p->initialised) return reply(error_reply(kNotInitialised));
    p->enabled = true;
    return reply(okay_reply());
  }
  if (name == "PDIS") {
    if (tracking_) return reply(error_reply(kInvalidMode));
    Port* p = find_port(handle);
    if (!p) return reply(error_reply(kInvalidHandle));
    if (!p->enabled) return reply(error_reply(kNotEnabled));
    p->enabled = false;
    return reply(okay_reply());
  }
  if (name == "PHINF") {
    Port* p = find_port(handle);
    if (!p) return reply(error_reply(kInvalidHandle));
    const std::string opt = params.size() > 2 ? params.substr(2) : "0001";
    if (opt.size() != 4 || !is_hex(opt)) return reply(error_reply(kOutOfRange));
    const unsigned option = parse_hex(opt);
    if ((option & ~0x0005u) != 0 || option == 0) return reply(error_reply(kOutOfRange));  // only basic + part number
    const SimTool* tool = p->tool_index >= 0 ? &scenario_.tools[static_cast<std::size_t>(p->tool_index)] : nullptr;
    const std::uint32_t status = (tool ? ndi::kPortOccupied : 0) | (p->initialised ? ndi::kPortInitialised : 0) |
                                  (p->enabled ? ndi::kPortEnabled : 0);
    std::string s;
    if (option & 0x0001) {
      // type(8) manufacturer(12) revision(3) serial(8) status(2)
      s += tool ? "02000000" : "00000000";
      s += tool ? "NDI         " : "            ";
      s += "000";
      s += tool ? tool->serial : "00000000";
      s += hex_field(status, 2);
    }
    if (option & 0x0004) {
      std::string part = tool ? tool->name : "";
      part.resize(20, ' ');
      s += part;
    }
    return reply(text_reply(s));
  }
  if (name == "TSTART") {
    if (tracking_) return reply(error_reply(kInvalidMode));
    tracking_ = true;
    if (!first_tstart_s_) first_tstart_s_ = now_s;
    return reply(okay_reply());
  }
  if (name == "TSTOP") {
    if (!tracking_) return reply(error_reply(kInvalidMode));
    tracking_ = false;
    return reply(okay_reply());
  }
  if (name == "TX" || name == "BX") return reply_tracking(name == "BX", params, now_s);
  if (name == "BX2") {
    if (api_revision_ < "G.003") return reply(error_reply(kInvalidCommand));
    if (!tracking_) return reply(error_reply(kInvalidMode));
    if (params.find("--6d=tools") == std::string::npos) return reply(error_reply(kOutOfRange));  // the simulator models 6D data only
    Bytes out;
    ndi::encode_bx2(bx2_frame(frame_at(now_s), now_s), out);
    return reply(std::move(out));
  }
  return reply(error_reply(kInvalidCommand));
}

PolarisModel::Reply PolarisModel::reply_tracking(bool binary, const std::string& params, double now_s) {
  if (!tracking_) return reply(error_reply(kInvalidMode));
  const std::string opt = params.empty() ? "0001" : params;
  if (opt.size() != 4 || !is_hex(opt)) return reply(error_reply(kOutOfRange));
  const unsigned option = parse_hex(opt);
  if ((option & ~(unsigned{kReplyTransforms} | kReplyOutOfVolume)) != 0 || !(option & kReplyTransforms))
    return reply(error_reply(kOutOfRange));  // the simulator models transform data only
  return reply(tracking_reply(tracking_frame(frame_at(now_s), now_s, (option & kReplyOutOfVolume) != 0), binary));
}

double PolarisModel::frame_time_mono_s(std::uint32_t frame) const {
  return clock_origin_mono_s_ + boot_s_ + static_cast<double>(frame - scenario_.first_frame) / scenario_.frame_rate_hz;
}

ndi::TrackingReply PolarisModel::bx2_frame(std::uint32_t frame, double now_s) {
  ndi::TrackingReply all = tracking_frame(frame, now_s, true);
  ndi::TrackingReply out;
  for (std::size_t i = 0; i < all.count; ++i)
    if (all.handles[i].state != ndi::HandleState::Disabled) out.handles[out.count++] = all.handles[i];
  out.has_frame = true;
  out.frame = frame;
  out.has_device_time = true;
  out.device_time_ns = static_cast<std::int64_t>(std::llround(frame_time_mono_s(frame) * 1e9));
  return out;
}

ndi::TrackingReply PolarisModel::tracking_frame(std::uint32_t frame, double now_s, bool include_out_of_volume) {
  const double t_s = motion_time_s(frame);
  ndi::TrackingReply out;
  for (const auto& [h, p] : ports_) {
    if (out.count == out.handles.size()) break;  // more handles than a frame can carry
    ndi::HandleRecord& r = out.handles[out.count++];
    r.handle = h;
    r.frame_number = frame;
    if (!p.enabled) {
      r.state = ndi::HandleState::Disabled;
      continue;
    }
    r.state = ndi::HandleState::Missing;
    r.has_status = true;
    r.port_status = ndi::kPortInitialised | ndi::kPortEnabled;
    const SimTool* tool = p.tool_index >= 0 ? &scenario_.tools[static_cast<std::size_t>(p.tool_index)] : nullptr;
    TruthRow truth;
    truth.frame_number = frame;
    truth.handle = h;
    if (tool) {
      r.port_status |= ndi::kPortOccupied;
      truth.tool = tool->name;
      truth.X_NdiTool = tool->motion.X_NdiTool(t_s);
      const auto hidden = missing_until_.find(tool->name);
      const auto outside = out_of_volume_until_.find(tool->name);
      const bool is_hidden = hidden != missing_until_.end() && now_s < hidden->second;
      const bool is_outside = outside != out_of_volume_until_.end() && now_s < outside->second;
      if (is_outside) r.port_status |= ndi::kPortOutOfVolume;
      if (!is_hidden && (!is_outside || include_out_of_volume)) {
        const std::optional<MarkerFit> measured = measure_tool(scenario_.measurement, truth.X_NdiTool, tool->markers_Tool_mm,
                                                               p.tool_index, frame, tool->rms_error_mm);
        truth.dropped_out = !measured;
        if (measured) {
          r.state = ndi::HandleState::Valid;
          Eigen::Quaterniond q(measured->X_NdiTool.rotation());
          if (q.w() < 0) q.coeffs() *= -1.0;
          r.q_NdiTool_wxyz = {q.w(), q.x(), q.y(), q.z()};
          const Eigen::Vector3d p_mm = measured->X_NdiTool.translation();
          r.p_NdiTool_mm = {p_mm.x(), p_mm.y(), p_mm.z()};
          r.rms_error_mm = measured->rms_error_mm;
          truth.X_NdiTool_reported = measured->X_NdiTool;
          truth.rms_error_mm = measured->rms_error_mm;
          truth.valid = true;
        }
      }
    }
    truth.port_status = r.port_status;
    if (on_truth) on_truth(truth);
  }
  return out;
}

}  // namespace arnav::hil
