#include "appliance/app/swab.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <utility>

#include "appliance/app/config.hpp"
#include "protocol/yaml/yaml_reader.hpp"
#include "protocol/channels.hpp"
#include "protocol/clock.hpp"

namespace arnav::app {

std::string SwabConfig::channel() const { return channels::cloud(source); }

std::optional<SwabConfig> parse_swab_config(const std::string& text, const std::string& source, const std::vector<std::string>& tool_names,
                                            const std::vector<std::string>& input_names) {
  using Reader = yaml::YamlReader<ConfigError>;
  Reader r(source);
  const YAML::Node root = r.load_root(text);
  const YAML::Node s = root["swab"];
  if (!s) return std::nullopt;
  r.only(s, "swab", {"tool", "tip_mm", "input", "continuous", "min_spacing_mm", "points_per_message", "source"});
  SwabConfig c;
  if (!s["tool"]) r.fail(s, "swab.tool", "missing: the NDI tool whose tip is sampled (a name under tools:)");
  c.tool = r.get<std::string>(s["tool"], "swab.tool", "a string");
  if (std::find(tool_names.begin(), tool_names.end(), c.tool) == tool_names.end()) {
    std::string list;
    for (const auto& t : tool_names) list += (list.empty() ? "" : ", ") + t;
    r.fail(s["tool"], "swab.tool", "'" + c.tool + "' is not an NDI tool under tools: (" + (list.empty() ? "none configured" : list) + ")");
  }
  const YAML::Node tip = s["tip_mm"];
  if (!tip) r.fail(s, "swab.tip_mm", "missing: the tip in the tool frame, [x, y, z] mm (from the pivot calibration)");
  if (!tip.IsSequence() || tip.size() != 3) r.fail(tip, "swab.tip_mm", "expected [x, y, z] in mm");
  for (int k = 0; k < 3; ++k) {
    c.tip_Tool_mm[k] = r.get<double>(tip[static_cast<std::size_t>(k)], "swab.tip_mm", "a number");
    if (!std::isfinite(c.tip_Tool_mm[k]) || std::abs(c.tip_Tool_mm[k]) > 1000.0)
      r.fail(tip, "swab.tip_mm", "coordinates must be finite and within 1000 mm of the tool origin");
  }
  if (s["continuous"]) c.continuous = r.get<bool>(s["continuous"], "swab.continuous", "true or false");
  if (s["input"]) {
    if (c.continuous) r.fail(s["input"], "swab.input", "give either an input (sample while held) or continuous: true, not both");
    c.input = r.get<std::string>(s["input"], "swab.input", "a string");
    if (std::find(input_names.begin(), input_names.end(), c.input) == input_names.end()) {
      std::string list;
      for (const auto& t : input_names) list += (list.empty() ? "" : ", ") + t;
      r.fail(s["input"], "swab.input",
             "'" + c.input + "' is not a CAN input under can.inputs (" + (list.empty() ? "no can: section" : list) + ")");
    }
  } else if (!c.continuous) {
    r.fail(s, "swab.input", "missing: the CAN input held while swabbing (a name under can.inputs), or continuous: true");
  }
  if (s["min_spacing_mm"]) {
    c.min_spacing_mm = r.get<double>(s["min_spacing_mm"], "swab.min_spacing_mm", "a number");
    if (!(c.min_spacing_mm >= 0.0) || c.min_spacing_mm > 50.0) r.fail(s["min_spacing_mm"], "swab.min_spacing_mm", "must be between 0 and 50 mm");
  }
  if (s["points_per_message"]) {
    c.points_per_message = r.get<int>(s["points_per_message"], "swab.points_per_message", "an integer");
    if (c.points_per_message < 1 || c.points_per_message > 10000)
      r.fail(s["points_per_message"], "swab.points_per_message", "must be between 1 and 10000");
  }
  if (s["source"]) {
    c.source = r.get<std::string>(s["source"], "swab.source", "a string");
    if (c.source.empty()) r.fail(s["source"], "swab.source", "empty");
    for (char ch : c.source)
      if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '-'))
        r.fail(s["source"], "swab.source", "'" + c.source + "' may only hold letters, digits, '_' and '-' (it names an LCM channel)");
  }
  return c;
}

std::optional<SwabConfig> load_swab_config(const std::string& path, const std::vector<std::string>& tool_names,
                                           const std::vector<std::string>& input_names) {
  return parse_swab_config(read_config_text(path), path, tool_names, input_names);
}

SwabSampler::SwabSampler(seal::SealedLcm& lcm, SwabConfig config) : lcm_(lcm), config_(std::move(config)), channel_(config_.channel()) {
  msg_.source = config_.source;
  msg_.num_points = msg_.num_normals = msg_.num_ids = 0;
}

void SwabSampler::set_input(const std::string& input_name, bool pressed) {
  if (config_.continuous || input_name != config_.input) return;
  const bool was = pressed_.exchange(pressed);
  if (was && !pressed) release_pending_ = true;  // the NDI thread sends the rest
}

void SwabSampler::flush() {
  if (msg_.num_points == 0) return;
  msg_.publish_time_mono_us = monotonic_us();
  msg_.publish_time_wall_us = wall_us();
  msg_.sequence = sequence_++;
  lcm_.publish(channel_, &msg_);
  points_published_ += msg_.num_points;
  msg_.p_mm.clear();
  msg_.num_points = 0;
}

void SwabSampler::on_frame(const std::optional<Eigen::Isometry3d>& X_FrameTool, const std::string& frame, std::int64_t capture_wall_us) {
  if (release_pending_.exchange(false)) {
    flush();
    last_.reset();
  }
  if (!active() || !X_FrameTool) return;
  if (msg_.num_points > 0 && frame != msg_.frame_name) flush();  // never two frames in one message
  const Eigen::Vector3d tip = *X_FrameTool * config_.tip_Tool_mm;
  if (!tip.allFinite()) return;
  if (last_ && frame == msg_.frame_name && (tip - *last_).norm() < config_.min_spacing_mm) return;
  last_ = tip;
  if (msg_.num_points == 0) msg_.capture_time_wall_us = capture_wall_us;
  msg_.frame_name = frame;
  msg_.p_mm.push_back({tip.x(), tip.y(), tip.z()});
  ++msg_.num_points;
  if (msg_.num_points >= config_.points_per_message) flush();
}

}  // namespace arnav::app
