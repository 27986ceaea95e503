#include "hil_tests/attacker/bus_attacker.hpp"

#include <chrono>

#include "arnav/image_frame_t.hpp"
#include "arnav/input_event_t.hpp"
#include "arnav/tool_pose_t.hpp"
#include "protocol/channels.hpp"
#include "protocol/seal/envelope.hpp"

namespace arnav::hil {

namespace {
std::shared_ptr<const seal::SessionKey> own_key() {
  std::array<std::uint8_t, seal::kKeyBytes> b{};
  std::random_device rd;
  for (auto& x : b) x = static_cast<std::uint8_t>(rd());
  return std::make_shared<const seal::SessionKey>(b);
}
std::int64_t wall_us() {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
}
std::string key_of(const std::vector<std::uint8_t>& b) { return std::string(b.begin(), b.end()); }
}  // namespace

nlohmann::json AttackCounts::json() const {
  return {{"unsealed", unsealed}, {"forged", forged}, {"replayed", replayed}, {"tampered", tampered}, {"stale", stale}, {"total", total()}};
}

BusAttacker::BusAttacker(lcm::LCM& bus, AttackPlan plan) : bus_(bus), plan_(std::move(plan)), own_(own_key()) {
  if (plan_.earlier_log.empty()) return;
  lcm::LogFile log(plan_.earlier_log, "r");
  if (!log.good()) throw std::runtime_error(plan_.earlier_log + ": cannot open the earlier session's log");
  while (const lcm::LogEvent* ev = log.readNextEvent()) {
    const auto* p = static_cast<const std::uint8_t*>(ev->data);
    earlier_.push_back({ev->channel, std::vector<std::uint8_t>(p, p + ev->datalen)});
  }
}

void BusAttacker::on_message(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
  const auto* p = static_cast<const std::uint8_t*>(rbuf->data);
  std::vector<std::uint8_t> bytes(p, p + rbuf->data_size);
  if (!seal::looks_sealed(bytes) || sent_.count(key_of(bytes))) return;
  captured_.push_back({channel, std::move(bytes)});
  if (captured_.size() > 400) captured_.pop_front();
}

void BusAttacker::send(const std::string& channel, const std::vector<std::uint8_t>& bytes) {
  sent_.insert(key_of(bytes));
  bus_.publish(channel, bytes.data(), static_cast<unsigned>(bytes.size()));
}

template <class Msg>
std::vector<std::uint8_t> BusAttacker::encode(const Msg& m) {
  std::vector<std::uint8_t> b(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(b.data(), 0, m.getEncodedSize());
  return b;
}

std::vector<std::uint8_t> BusAttacker::forged_pose(const std::string& tool) {
  tool_pose_t m{};
  m.tool_name = tool;
  m.source = tool_pose_t::SOURCE_CAMERA;
  m.frame_parent = "Cam";
  m.frame_child = "Tool";
  m.p_ParentChild_mm[0] = 80.0 + static_cast<double>(rng_() % 50);  // far from where the board is
  m.p_ParentChild_mm[2] = 300.0;
  m.q_ParentChild_wxyz[0] = 1.0;
  m.quality = 1.0f;
  m.status = tool_pose_t::STATUS_VALID;
  m.sequence = static_cast<std::int64_t>(counts_.total());
  m.device_frame_number = m.sequence;
  m.publish_time_wall_us = wall_us();
  return encode(m);
}

std::vector<std::uint8_t> BusAttacker::forged_pedal() {
  input_event_t m{};
  m.input_name = "pedal_cut";
  m.state = input_event_t::STATE_PRESSED;
  m.value = 1.0;
  m.device = "pedal";
  m.source_interface = "can0";
  m.sequence = static_cast<std::int64_t>(counts_.total());
  m.publish_time_wall_us = wall_us();
  return encode(m);
}

std::vector<std::uint8_t> BusAttacker::forged_frame() {
  image_frame_t m{};
  m.camera_name = plan_.camera;
  m.sequence = static_cast<std::int64_t>(counts_.total());
  m.width = 1280;
  m.height = 720;
  m.source_width = 1280;
  m.source_height = 720;
  m.channels = 3;
  m.encoding = image_frame_t::ENCODING_JPEG;
  m.data.resize(plan_.frame_bytes);
  for (auto& b : m.data) b = static_cast<std::uint8_t>(rng_() % 200);  // not a JPEG: an accepted one would fail to decode
  m.size = static_cast<std::int32_t>(m.data.size());
  m.capture_time_wall_us = wall_us();
  return encode(m);
}

std::vector<std::uint8_t> BusAttacker::seal_with_own_key(const std::string& channel, const std::vector<std::uint8_t>& plain) {
  std::vector<std::uint8_t> env;
  own_.seal(channel, plain, wall_us(), env);
  return env;
}

bool BusAttacker::inject() {
  const std::string pose_channel = channels::pose(turn_ % 4 < 2 ? plan_.tool : std::string("scalpel"));
  const std::string frame_channel = channels::frame(plan_.camera);
  const std::string input_channel(channels::kInput);
  for (unsigned tries = 0; tries < 12; ++tries) {
    switch (turn_++ % 12) {
      case 0: send(pose_channel, forged_pose(pose_channel.substr(channels::kPosePrefix.size()))); ++counts_.unsealed; return true;
      case 1: send(pose_channel, seal_with_own_key(pose_channel, forged_pose(pose_channel.substr(channels::kPosePrefix.size())))); ++counts_.forged; return true;
      case 2: send(input_channel, forged_pedal()); ++counts_.unsealed; return true;
      case 3: send(input_channel, seal_with_own_key(input_channel, forged_pedal())); ++counts_.forged; return true;
      case 4: send(frame_channel, forged_frame()); ++counts_.unsealed; return true;
      case 5: send(frame_channel, seal_with_own_key(frame_channel, forged_frame())); ++counts_.forged; return true;
      case 6:
      case 7: {  // replay: a captured message at least a few messages old, unchanged
        if (captured_.size() < 8) break;
        const Captured& c = captured_[rng_() % (captured_.size() - 4)];
        send(c.channel, c.bytes);
        ++counts_.replayed;
        return true;
      }
      case 8:
      case 9: {  // bit flip in the ciphertext or tag
        if (captured_.empty()) break;
        Captured c = captured_[rng_() % captured_.size()];
        const std::size_t at = seal::kHeaderBytes + rng_() % (c.bytes.size() - seal::kHeaderBytes);
        c.bytes[at] ^= static_cast<std::uint8_t>(1u << (rng_() % 8));
        send(c.channel, c.bytes);
        ++counts_.tampered;
        return true;
      }
      case 10: {  // a genuine message moved to the pedal's channel (the channel is authenticated)
        if (captured_.empty()) break;
        const Captured& c = captured_.back();
        if (c.channel == input_channel) break;
        send(input_channel, c.bytes);
        ++counts_.tampered;
        return true;
      }
      case 11: {  // an earlier session's message
        if (earlier_.empty()) break;
        const Captured& c = earlier_[earlier_next_++ % earlier_.size()];
        // The same bytes twice would read as a replay the second time: once each.
        if (earlier_next_ > earlier_.size()) break;
        send(c.channel, c.bytes);
        ++counts_.stale;
        return true;
      }
    }
  }
  return false;
}

}  // namespace arnav::hil
