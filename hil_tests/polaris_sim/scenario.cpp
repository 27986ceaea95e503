#include "hil_tests/polaris_sim/scenario.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>

namespace arnav::hil {
namespace {

double parse_number(const std::string& token, const std::string& where, const char* what) {
  try {
    std::size_t used = 0;
    const double v = std::stod(token, &used);
    if (used != token.size() || !std::isfinite(v)) throw std::invalid_argument(token);
    return v;
  } catch (const std::exception&) {
    throw ScenarioError(where + ": " + what + " must be a number, got '" + token + "'");
  }
}

double parse_seconds(const std::string& token, const std::string& where) {
  const double s = parse_number(token, where, "duration (s)");
  if (s < 0.0 || s > 3600.0) throw ScenarioError(where + ": duration " + token + " s is outside [0, 3600]");
  return s;
}

int parse_count(const std::string& token, const std::string& where) {
  const double c = parse_number(token, where, "count");
  if (c < 1 || c > 100000 || c != std::floor(c)) throw ScenarioError(where + ": count must be an integer in [1, 100000], got " + token);
  return static_cast<int>(c);
}

}  // namespace

FaultCommand parse_fault(const std::string& line, const std::string& where) {
  std::istringstream in(line);
  std::vector<std::string> w{std::istream_iterator<std::string>(in), std::istream_iterator<std::string>()};
  if (w.empty()) throw ScenarioError(where + ": empty fault command");
  using K = FaultCommand::Kind;
  static const std::map<std::string, std::pair<K, std::string>> kinds = {
      {"cable_pull", {K::kCablePull, "SECONDS"}}, {"reset", {K::kReset, ""}},
      {"drop_bytes", {K::kDropBytes, "[N]"}},     {"garble", {K::kGarble, "[N]"}},
      {"bad_crc", {K::kBadCrc, "[N]"}},           {"partial", {K::kPartial, ""}},
      {"chunked", {K::kChunked, "SECONDS"}},      {"garbage", {K::kGarbage, "[N]"}},
      {"missing", {K::kMissing, "TOOL SECONDS"}}, {"out_of_volume", {K::kOutOfVolume, "TOOL SECONDS"}},
      {"slow", {K::kSlow, "DELAY_S [N]"}},        {"no_reply", {K::kNoReply, "[N]"}},
      {"error", {K::kError, "HEXCODE [N]"}},      {"baud_mismatch", {K::kBaudMismatch, "[BAUD]"}},
  };
  const auto it = kinds.find(w[0]);
  if (it == kinds.end()) {
    std::string names;
    for (const auto& [name, _] : kinds) names += (names.empty() ? "" : ", ") + name;
    throw ScenarioError(where + ": unknown fault '" + w[0] + "' (known: " + names + ")");
  }
  FaultCommand f;
  f.kind = it->second.first;
  f.text = line;
  const std::string usage = where + ": usage '" + w[0] + (it->second.second.empty() ? "" : " " + it->second.second) + "'";
  const auto need = [&](std::size_t lo, std::size_t hi) {
    if (w.size() < lo + 1 || w.size() > hi + 1) throw ScenarioError(usage + ", got '" + line + "'");
  };
  switch (f.kind) {
    case K::kCablePull:
    case K::kChunked:
      need(1, 1);
      f.duration_s = parse_seconds(w[1], where);
      break;
    case K::kReset:
    case K::kPartial:
      need(0, 0);
      break;
    case K::kDropBytes:
    case K::kGarble:
    case K::kBadCrc:
    case K::kGarbage:
    case K::kNoReply:
      need(0, 1);
      if (w.size() == 2) f.count = parse_count(w[1], where);
      break;
    case K::kMissing:
    case K::kOutOfVolume:
      need(2, 2);
      f.tool = w[1];
      f.duration_s = parse_seconds(w[2], where);
      break;
    case K::kSlow:
      need(1, 2);
      f.delay_s = parse_seconds(w[1], where);
      if (w.size() == 3) f.count = parse_count(w[2], where);
      break;
    case K::kError: {
      need(1, 2);
      if (w[1].size() != 2 || w[1].find_first_not_of("0123456789ABCDEFabcdef") != std::string::npos)
        throw ScenarioError(where + ": error code must be two hex digits (e.g. 0C), got '" + w[1] + "'");
      f.code = static_cast<std::uint8_t>(std::stoul(w[1], nullptr, 16));
      if (w.size() == 3) f.count = parse_count(w[2], where);
      break;
    }
    case K::kBaudMismatch:
      need(0, 1);
      if (w.size() == 2) {
        const double b = parse_number(w[1], where, "baud");
        static const int rates[] = {9600, 14400, 19200, 38400, 57600, 115200, 230400, 921600, 1228739};
        bool ok = false;
        for (int r : rates) ok = ok || b == r;
        if (!ok) throw ScenarioError(where + ": baud " + w[1] + " is not a Polaris rate (9600 ... 1228739)");
        f.baud = static_cast<int>(b);
      }
      break;
  }
  return f;
}

std::vector<std::uint8_t> read_rom(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw ScenarioError("cannot read tool definition file " + file.string() + ": check the path");
  std::vector<std::uint8_t> rom((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (rom.size() < 4 || rom.size() > 1024 || rom[0] != 'N' || rom[1] != 'D' || rom[2] != 'I' || rom[3] != 0)
    throw ScenarioError(file.string() + " is not an NDI tool definition (.rom files start with 'NDI\\0' and hold at most 1024 bytes)");
  return rom;
}

void add_tool_spec(Scenario& scenario, const std::string& spec) {
  const auto eq = spec.find('=');
  if (eq == std::string::npos || eq == 0 || eq + 1 == spec.size())
    throw ScenarioError("--tool '" + spec + "': expected NAME=ROM_PATH, e.g. pointer=data/ndi_roms/8700340.rom");
  SimTool t;
  t.name = spec.substr(0, eq);
  t.rom_path = spec.substr(eq + 1);
  t.rom = read_rom(t.rom_path);
  if (auto m = rom_marker_positions(t.rom)) t.markers_Tool_mm = std::move(*m);
  t.motion = default_motion(static_cast<int>(scenario.tools.size()));
  scenario.tools.push_back(std::move(t));
}

namespace {

Eigen::Vector3d vec3(const YAML::Node& n, const std::string& where) {
  if (!n.IsSequence() || n.size() != 3) throw ScenarioError(where + ": expected a list of 3 numbers");
  Eigen::Vector3d v;
  for (int i = 0; i < 3; ++i) v[i] = n[i].as<double>();
  if (!v.allFinite()) throw ScenarioError(where + ": values must be finite");
  return v;
}

double number(const YAML::Node& n, const std::string& where, double lo, double hi) {
  const double v = n.as<double>();
  if (!(v >= lo && v <= hi)) throw ScenarioError(where + ": " + std::to_string(v) + " is outside [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
  return v;
}

void check_keys(const YAML::Node& map, std::initializer_list<const char*> known, const std::string& where) {
  for (const auto& kv : map) {
    const std::string key = kv.first.as<std::string>();
    bool ok = false;
    for (const char* k : known) ok = ok || key == k;
    if (!ok) throw ScenarioError(where + ": unknown key '" + key + "'");
  }
}

// motion: {phantom: RECORDING, tool: NAME, X_NdiModel: [16 numbers, row-major], start_s: S}
ToolMotion parse_phantom_motion(const YAML::Node& n, const std::string& where, int index, const Scenario& s,
                                const std::filesystem::path& base_dir) {
  check_keys(n, {"phantom", "tool", "X_NdiModel", "start_s"}, where);
  ToolMotion m = default_motion(index);
  auto path = std::make_shared<PhantomToolPath>();
  const std::filesystem::path file = base_dir / n["phantom"].as<std::string>();
  try {
    path->recording = std::make_shared<const camera_sim::PhantomRecording>(camera_sim::read_phantom_recording(file));
  } catch (const camera_sim::PhantomError& e) {
    throw ScenarioError(where + ".phantom: " + e.what());
  }
  const std::string tool = n["tool"] ? n["tool"].as<std::string>() : path->recording->tool_names.empty() ? "" : path->recording->tool_names[0];
  path->tool = path->recording->tool_index(tool);
  if (path->tool < 0) throw ScenarioError(where + ".tool: the recording " + file.string() + " has no tool '" + tool + "'");
  if (!n["X_NdiModel"]) throw ScenarioError(where + ".X_NdiModel: missing (the phantom's model frame in the tracker frame, 16 numbers row-major)");
  const YAML::Node x = n["X_NdiModel"];
  if (!x.IsSequence() || x.size() != 16) throw ScenarioError(where + ".X_NdiModel: expected 16 numbers (4x4 row-major)");
  Eigen::Matrix4d M;
  for (int i = 0; i < 16; ++i) M(i / 4, i % 4) = x[static_cast<std::size_t>(i)].as<double>();
  const Eigen::Matrix3d R = M.topLeftCorner<3, 3>();
  if (!M.allFinite() || !(R.transpose() * R).isIdentity(1e-6) || std::abs(R.determinant() - 1.0) > 1e-6 ||
      !M.row(3).isApprox(Eigen::RowVector4d(0, 0, 0, 1)))
    throw ScenarioError(where + ".X_NdiModel: not a rigid transform (orthonormal rotation, det +1, last row 0 0 0 1)");
  path->X_NdiModel.matrix() = M;
  if (n["start_s"]) path->start_s = number(n["start_s"], where + ".start_s", -1e6, 1e6);
  path->t0_s = static_cast<double>(s.first_frame) / s.frame_rate_hz;
  m.phantom = std::move(path);
  return m;
}

Eigen::Isometry3d rigid_16(const YAML::Node& x, const std::string& where) {
  if (!x.IsSequence() || x.size() != 16) throw ScenarioError(where + ": expected 16 numbers (4x4 row-major)");
  Eigen::Matrix4d M;
  for (int i = 0; i < 16; ++i) M(i / 4, i % 4) = number(x[static_cast<std::size_t>(i)], where, -1e6, 1e6);
  const Eigen::Matrix3d R = M.topLeftCorner<3, 3>();
  if (!M.allFinite() || !(R.transpose() * R).isIdentity(1e-6) || std::abs(R.determinant() - 1.0) > 1e-6 ||
      !M.row(3).isApprox(Eigen::RowVector4d(0, 0, 0, 1)))
    throw ScenarioError(where + ": not a rigid transform (orthonormal rotation, det +1, last row 0 0 0 1)");
  Eigen::Isometry3d X;
  X.matrix() = M;
  return X;
}

// motion: {path: FILE.csv, X_NdiModel: [16 numbers, row-major], start_s: S}
ToolMotion parse_path_motion(const YAML::Node& n, const std::string& where, int index, const Scenario& s,
                             const std::filesystem::path& base_dir) {
  check_keys(n, {"path", "X_NdiModel", "start_s"}, where);
  ToolMotion m = default_motion(index);
  const std::filesystem::path file = base_dir / n["path"].as<std::string>();
  std::ifstream in(file);
  if (!in) throw ScenarioError(where + ".path: cannot read " + file.string() + " (a CSV of t_s, x_mm, y_mm, z_mm[, qw, qx, qy, qz] rows)");
  std::stringstream text;
  text << in.rdbuf();
  auto path = std::make_shared<ScriptedToolPath>();
  try {
    *path = parse_tool_path_csv(text.str(), file.string());
  } catch (const ToolPathError& e) {
    throw ScenarioError(where + ".path: " + e.what());
  }
  if (!n["X_NdiModel"]) throw ScenarioError(where + ".X_NdiModel: missing (the model frame in the tracker frame, 16 numbers row-major)");
  path->X_NdiModel = rigid_16(n["X_NdiModel"], where + ".X_NdiModel");
  if (n["start_s"]) path->start_s = number(n["start_s"], where + ".start_s", -1e6, 1e6);
  path->t0_s = static_cast<double>(s.first_frame) / s.frame_rate_hz;
  for (const Eigen::Vector3d& p : path->p_Model_mm)
    if (((path->X_NdiModel * p).array().abs() > 9999.0).any())
      throw ScenarioError(where + ": the path leaves +-9999 mm in the tracker frame (the TX field width): check X_NdiModel");
  m.path = std::move(path);
  return m;
}

ToolMotion parse_motion(const YAML::Node& n, const std::string& where, int index) {
  if (!n.IsMap()) throw ScenarioError(where + ": expected a map");
  check_keys(n, {"center_mm", "amplitude_mm", "frequency_hz", "phase_rad", "base_axis_angle", "rotation_axis",
                 "rotation_amplitude_rad", "rotation_frequency_hz"}, where);
  ToolMotion m = default_motion(index);
  if (n["center_mm"]) m.center_mm = vec3(n["center_mm"], where + ".center_mm");
  if (n["amplitude_mm"]) m.amplitude_mm = vec3(n["amplitude_mm"], where + ".amplitude_mm");
  if (n["frequency_hz"]) m.frequency_hz = vec3(n["frequency_hz"], where + ".frequency_hz");
  if (n["phase_rad"]) m.phase_rad = vec3(n["phase_rad"], where + ".phase_rad");
  if (n["base_axis_angle"]) {
    const YAML::Node a = n["base_axis_angle"];
    if (!a.IsSequence() || a.size() != 4) throw ScenarioError(where + ".base_axis_angle: expected [ax, ay, az, angle_rad]");
    const Eigen::Vector3d axis(a[0].as<double>(), a[1].as<double>(), a[2].as<double>());
    if (!(axis.norm() > 1e-9)) throw ScenarioError(where + ".base_axis_angle: zero axis");
    m.q_base = Eigen::Quaterniond(Eigen::AngleAxisd(a[3].as<double>(), axis.normalized()));
  }
  if (n["rotation_axis"]) {
    m.rotation_axis = vec3(n["rotation_axis"], where + ".rotation_axis");
    if (!(m.rotation_axis.norm() > 1e-9)) throw ScenarioError(where + ".rotation_axis: zero axis");
  }
  if (n["rotation_amplitude_rad"]) m.rotation_amplitude_rad = number(n["rotation_amplitude_rad"], where + ".rotation_amplitude_rad", -10, 10);
  if (n["rotation_frequency_hz"]) m.rotation_frequency_hz = number(n["rotation_frequency_hz"], where + ".rotation_frequency_hz", 0, 100);
  for (int i = 0; i < 3; ++i)
    if (std::abs(m.center_mm[i]) + std::abs(m.amplitude_mm[i]) > 9999.0)
      throw ScenarioError(where + ": positions must stay within +-9999 mm (the TX field width)");
  return m;
}

// measurement: {model: ideal|realistic, marker_noise_rms_mm: 0.25, dropout_rate: 0.002, seed: 1}
MeasurementModel parse_measurement(const YAML::Node& n, const std::string& where) {
  if (!n.IsMap()) throw ScenarioError(where + ": expected a map {model: ideal|realistic, marker_noise_rms_mm, dropout_rate, seed}");
  check_keys(n, {"model", "marker_noise_rms_mm", "dropout_rate", "seed"}, where);
  const std::string kind = n["model"] ? n["model"].as<std::string>() : "realistic";
  if (kind != "ideal" && kind != "realistic") throw ScenarioError(where + ".model: '" + kind + "' is neither 'ideal' nor 'realistic'");
  MeasurementModel m = kind == "ideal" ? MeasurementModel{} : MeasurementModel::realistic();
  if (n["marker_noise_rms_mm"]) m.marker_noise_rms_mm = number(n["marker_noise_rms_mm"], where + ".marker_noise_rms_mm", 0, 10);
  if (n["dropout_rate"]) m.dropout_rate = number(n["dropout_rate"], where + ".dropout_rate", 0, 0.5);
  if (n["seed"]) m.seed = static_cast<std::uint64_t>(number(n["seed"], where + ".seed", 0, 9e15));
  return m;
}

// markers_mm: [[x, y, z], ...] in the tool frame: >= 3, not collinear.
std::vector<Eigen::Vector3d> parse_markers(const YAML::Node& n, const std::string& where) {
  if (!n.IsSequence()) throw ScenarioError(where + ": expected a list of [x, y, z] marker positions (mm, tool frame)");
  std::vector<Eigen::Vector3d> m;
  for (std::size_t i = 0; i < n.size(); ++i) m.push_back(vec3(n[i], where + "[" + std::to_string(i) + "]"));
  if (!markers_define_a_pose(m)) throw ScenarioError(where + ": needs >= 3 markers that are not collinear (spread >= 1 mm off their main axis)");
  return m;
}

}  // namespace

void set_sensors(Scenario& scenario, const std::string& sensors, std::optional<std::uint64_t> seed) {
  if (sensors == "ideal") {
    scenario.measurement = MeasurementModel{};
  } else if (sensors == "realistic") {
    if (scenario.measurement.ideal) scenario.measurement = MeasurementModel::realistic(scenario.measurement.seed);
  } else if (!sensors.empty()) {
    throw ScenarioError("--sensors '" + sensors + "': expected 'ideal' or 'realistic'");
  }
  if (seed) scenario.measurement.seed = *seed;
}

Scenario parse_scenario(const std::string& yaml_text, const std::string& source_name, const std::filesystem::path& base_dir) {
  Scenario s;
  try {
    const YAML::Node root = YAML::Load(yaml_text);
    if (!root.IsMap()) throw ScenarioError(source_name + ": expected a YAML map at the top level");
    check_keys(root, {"frame_rate_hz", "first_frame", "serial_number", "tools", "faults", "epoch_mono_us", "measurement"}, source_name);
    if (root["measurement"]) s.measurement = parse_measurement(root["measurement"], source_name + ": measurement");
    if (root["epoch_mono_us"]) s.epoch_mono_us = static_cast<std::int64_t>(number(root["epoch_mono_us"], source_name + ": epoch_mono_us", 0, 9e15));
    if (root["frame_rate_hz"]) s.frame_rate_hz = number(root["frame_rate_hz"], source_name + ": frame_rate_hz", 1.0, kMaxFrameRateHz);
    if (root["first_frame"]) s.first_frame = static_cast<std::uint32_t>(number(root["first_frame"], source_name + ": first_frame", 0, 4e9));
    if (root["serial_number"]) s.serial_number = root["serial_number"].as<std::string>();
    if (const YAML::Node tools = root["tools"]) {
      if (!tools.IsSequence()) throw ScenarioError(source_name + ": tools must be a list");
      for (std::size_t i = 0; i < tools.size(); ++i) {
        const std::string where = source_name + ": tools[" + std::to_string(i) + "]";
        const YAML::Node t = tools[i];
        if (!t.IsMap()) throw ScenarioError(where + ": expected a map with name, rom, motion");
        check_keys(t, {"name", "rom", "serial", "motion", "rms_error_mm", "markers_mm"}, where);
        SimTool tool;
        if (!t["name"]) throw ScenarioError(where + ": missing 'name'");
        tool.name = t["name"].as<std::string>();
        if (tool.name.empty() || tool.name.find_first_of(" \t\n") != std::string::npos)
          throw ScenarioError(where + ": tool name must be one word");
        for (const SimTool& other : s.tools)
          if (other.name == tool.name) throw ScenarioError(where + ": duplicate tool name '" + tool.name + "'");
        if (t["rom"]) {
          tool.rom_path = (base_dir / t["rom"].as<std::string>()).string();
          tool.rom = read_rom(tool.rom_path);
          if (auto m = rom_marker_positions(tool.rom)) tool.markers_Tool_mm = std::move(*m);
        }
        if (t["markers_mm"]) tool.markers_Tool_mm = parse_markers(t["markers_mm"], where + ".markers_mm");
        if (t["serial"]) {
          tool.serial = t["serial"].as<std::string>();
          if (tool.serial.size() != 8) throw ScenarioError(where + ".serial: must be 8 characters");
        }
        if (t["rms_error_mm"]) tool.rms_error_mm = number(t["rms_error_mm"], where + ".rms_error_mm", 0, 9);
        if (t["motion"] && t["motion"].IsMap() && t["motion"]["path"])
          tool.motion = parse_path_motion(t["motion"], where + ".motion", static_cast<int>(i), s, base_dir);
        else if (t["motion"] && t["motion"].IsMap() && t["motion"]["phantom"])
          tool.motion = parse_phantom_motion(t["motion"], where + ".motion", static_cast<int>(i), s, base_dir);
        else
          tool.motion = t["motion"] ? parse_motion(t["motion"], where + ".motion", static_cast<int>(i)) : default_motion(static_cast<int>(i));
        s.tools.push_back(std::move(tool));
      }
    }
    if (const YAML::Node faults = root["faults"]) {
      if (!faults.IsSequence()) throw ScenarioError(source_name + ": faults must be a list");
      for (std::size_t i = 0; i < faults.size(); ++i) {
        const std::string where = source_name + ": faults[" + std::to_string(i) + "]";
        const YAML::Node f = faults[i];
        if (!f.IsMap() || !f["at_s"] || !f["do"]) throw ScenarioError(where + ": expected {at_s: SECONDS, do: \"FAULT ARGS\"}");
        check_keys(f, {"at_s", "do"}, where);
        TimedFault tf;
        tf.at_s = number(f["at_s"], where + ".at_s", 0, 86400);
        tf.fault = parse_fault(f["do"].as<std::string>(), where);
        s.faults.push_back(std::move(tf));
      }
    }
  } catch (const YAML::Exception& e) {
    throw ScenarioError(source_name + ": line " + std::to_string(e.mark.line + 1) + ": " + e.msg);
  }
  return s;
}

Scenario load_scenario(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) throw ScenarioError("cannot read scenario file " + file.string());
  std::stringstream text;
  text << in.rdbuf();
  return parse_scenario(text.str(), file.string(), file.parent_path());
}

}  // namespace arnav::hil
