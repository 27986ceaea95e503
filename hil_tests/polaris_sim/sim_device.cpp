#include "hil_tests/polaris_sim/sim_device.hpp"

namespace arnav::hil {

std::vector<PolarisModel::Reply> ModelDevice::receive(std::span<const std::uint8_t> bytes, double now_s) {
  if (errors_left_ == 0 && swallow_left_ == 0) return model_.receive(bytes, now_s);
  // Command-level faults: the command is lost or refused before the device executes it,
  // so the device state stays consistent with what the host was told.
  std::vector<PolarisModel::Reply> out;
  for (std::uint8_t b : bytes) {
    line_.push_back(b);
    if (b != '\r') continue;
    std::vector<std::uint8_t> line;
    line.swap(line_);
    if (swallow_left_ > 0) {
      --swallow_left_;
      continue;
    }
    if (errors_left_ > 0) {
      --errors_left_;
      PolarisModel::Reply r{error_reply(error_code_), std::string(line.begin(), line.end() - 1), 0};
      out.push_back(std::move(r));
      continue;
    }
    for (auto& r : model_.receive(line, now_s)) out.push_back(std::move(r));
  }
  if (errors_left_ == 0 && swallow_left_ == 0 && !line_.empty()) {
    std::vector<std::uint8_t> rest;
    rest.swap(line_);
    for (auto& r : model_.receive(rest, now_s)) out.push_back(std::move(r));
  }
  return out;
}

bool ModelDevice::force_errors(std::uint8_t code, int count) {
  error_code_ = code;
  errors_left_ = count;
  return true;
}

bool ModelDevice::swallow_commands(int count) {
  swallow_left_ = count;
  return true;
}

bool ModelDevice::hide_tool(const std::string& tool, double until_s, bool out_of_volume) {
  if (!model_.knows_tool(tool)) return false;
  if (out_of_volume)
    model_.push_out_of_volume_until(tool, until_s);
  else
    model_.hide_tool_until(tool, until_s);
  return true;
}

}  // namespace arnav::hil
