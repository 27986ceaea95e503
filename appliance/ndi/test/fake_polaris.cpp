#include "appliance/ndi/test/fake_polaris.hpp"

#include <cmath>
#include <thread>

#include "appliance/ndi/bx.hpp"
#include "appliance/ndi/command.hpp"
#include "appliance/ndi/hex.hpp"
#include "appliance/ndi/reply.hpp"

namespace arnav::ndi::test {

void FakeDevice::reset_device() {
  device_baud = 9600;
  initialised = false;
  tracking = false;
  roms.clear();
  enabled.clear();
  line.clear();
}

void FakeDevice::spontaneous_reset() {
  reset_device();
  to_host.clear();
  reply(encode_reply("RESET"));
}

void FakeDevice::reply(const std::string& bytes) {
  if (drop_replies > 0) {
    --drop_replies;
    return;
  }
  if (host_baud != device_baud) return;  // host cannot decode it: lost
  to_host.insert(to_host.end(), bytes.begin(), bytes.end());
}

void FakeDevice::on_host_bytes(const std::uint8_t* data, std::size_t n) {
  bytes_from_host += n;
  if (host_baud != device_baud) return;  // framing errors at the device: ignored
  for (std::size_t i = 0; i < n; ++i) {
    if (data[i] == '\r') {
      std::string cmd;
      cmd.swap(line);
      handle_command(cmd);
    } else {
      line += static_cast<char>(data[i]);
    }
  }
}

void FakeDevice::handle_command(const std::string& text) {
  auto c = decode_command(text);
  if (!c) return reply(encode_reply("ERROR01"));
  commands.emplace_back(c->name);
  if (c->has_crc && !c->crc_ok) return reply(encode_reply("ERROR04"));
  const std::string name(c->name), p(c->params);
  if (name == "INIT") {
    if (tracking && !init_ok_while_tracking) return reply(encode_reply("ERROR0C"));
    initialised = true;
    return reply(encode_reply("OKAY"));
  }
  if (name == "COMM") {
    comm_params.push_back(p);
    auto rate = p.empty() ? std::nullopt : baud_from_code(p[0]);
    if (!rate || refuse_rates.count(*rate)) return reply(encode_reply("ERROR06"));
    reply(encode_reply("OKAY"));
    device_baud = broken_rates.count(*rate) ? -*rate : *rate;  // a broken rate never matches the host
    return;
  }
  if (!initialised && name != "VER" && name != "TSTOP") return reply(encode_reply("ERROR10"));
  if (name == "VER") return reply(encode_reply(firmware));
  if (tracking && (name == "PHRQ" || name == "PVWR" || name == "PINIT" || name == "PENA" || name == "COMM"))
    return reply(encode_reply("ERROR0C"));
  if (name == "PHSR") return reply(encode_reply("00"));
  if (name == "PHF") return reply(encode_reply("OKAY"));
  if (name == "PHRQ") {
    std::uint8_t h = next_handle++;
    roms[h];
    return reply(encode_reply(hex2(h)));
  }
  if (name == "PVWR") {
    if (p.size() != 134) return reply(encode_reply("ERROR07"));
    auto h = parse_hex<std::uint8_t>(p.substr(0, 2));
    auto addr = parse_hex<std::uint16_t>(p.substr(2, 4));
    if (!h || !addr || !roms.count(*h)) return reply(encode_reply("ERROR08"));
    auto& rom = roms[*h];
    if (rom.size() < *addr + 64u) rom.resize(*addr + 64u);
    for (int i = 0; i < 64; ++i) rom[*addr + i] = *parse_hex<std::uint8_t>(p.substr(6 + 2 * i, 2));
    return reply(encode_reply("OKAY"));
  }
  if (name == "PINIT") {
    auto h = parse_hex<std::uint8_t>(p);
    if (!h || !roms.count(*h)) return reply(encode_reply("ERROR08"));
    if (roms[*h].size() < 4 || roms[*h][0] != 'N') return reply(encode_reply("ERROR41"));
    return reply(encode_reply("OKAY"));
  }
  if (name == "PHINF") return reply(encode_reply("08000000NDI         00008700340" "31"));
  if (name == "PENA") {
    auto h = parse_hex<std::uint8_t>(p.substr(0, 2));
    if (!h || !roms.count(*h)) return reply(encode_reply("ERROR08"));
    enabled.insert(*h);
    return reply(encode_reply("OKAY"));
  }
  if (name == "TSTART") {
    tracking = true;
    return reply(encode_reply("OKAY"));
  }
  if (name == "TSTOP") {
    tracking = false;
    return reply(encode_reply("OKAY"));
  }
  if (name == "BX" || name == "TX") {
    if (!tracking) return reply(encode_reply("ERROR0C"));
    frame += frame_step;
    TrackingReply t;
    for (std::uint8_t h : enabled) {
      auto& r = t.handles[t.count++];
      r.handle = h;
      r.state = HandleState::Valid;
      const double a = 0.01 * frame;
      r.q_NdiTool_wxyz = {std::cos(a / 2), 0.0, 0.0, std::sin(a / 2)};
      r.p_NdiTool_mm = {10.0 * h, -20.0, -1500.0 + 0.5 * frame};
      r.rms_error_mm = 0.15;
      r.has_status = true;
      r.port_status = 0x31;
      r.frame_number = frame;
    }
    if (name == "TX") return reply(encode_reply(format_tx_body(t)));
    ++bx_count;
    std::vector<std::uint8_t> f;
    encode_bx(t, f);
    if (bx_always_corrupt || (bx_corrupt_every > 0 && bx_count % bx_corrupt_every == 0)) f[f.size() - 3] ^= 0x5A;
    return reply(garbage_before_bx + std::string(f.begin(), f.end()));
  }
  return reply(encode_reply("ERROR01"));
}

FakeTransport::FakeTransport(std::shared_ptr<FakeDevice> dev) : dev_(std::move(dev)) { ++dev_->opens; }

std::size_t FakeTransport::read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout) {
  if (dev_->unplugged) throw PortLost("fake0: device unplugged");
  if (dev_->to_host.empty()) {
    std::this_thread::sleep_for(timeout);  // nothing will arrive: the peer is synchronous
    return 0;
  }
  std::size_t n = std::min(buffer.size(), dev_->to_host.size());
  if (dev_->chunk > 0) n = std::min(n, dev_->chunk);
  for (std::size_t i = 0; i < n; ++i) {
    buffer[i] = dev_->to_host.front();
    dev_->to_host.pop_front();
  }
  return n;
}

void FakeTransport::write(std::span<const std::uint8_t> bytes) {
  if (dev_->unplugged) throw PortLost("fake0: device unplugged");
  dev_->on_host_bytes(bytes.data(), bytes.size());
}

void FakeTransport::send_break(std::chrono::milliseconds) {
  ++dev_->breaks;
  if (!dev_->break_resets) return;
  dev_->reset_device();
  dev_->to_host.clear();
  dev_->reply(encode_reply("RESET"));  // at 9600, as the host now is
}

TransportFactory fake_factory(std::shared_ptr<FakeDevice> dev) {
  return [dev]() -> std::unique_ptr<Transport> {
    if (dev->unplugged) throw PortError("fake0: no such port");
    return std::make_unique<FakeTransport>(dev);
  };
}

}  // namespace arnav::ndi::test
