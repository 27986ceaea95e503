#include "host/app/session_config.hpp"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "protocol/yaml/yaml_reader.hpp"
#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/rigid_transform_file.hpp"
#include "host/register/point_files.hpp"
#include "host/mesh/load_error.hpp"

namespace arnav::host {
namespace {

using Reader = yaml::YamlReader<SessionError>;

std::string resolve(const std::string& base_dir, const std::string& p) {
  const std::filesystem::path path(p);
  return path.is_absolute() ? p : (std::filesystem::path(base_dir) / path).lexically_normal().string();
}

int line_of(const YAML::Node& n) { return n.IsDefined() && n.Mark().line >= 0 ? n.Mark().line + 1 : 1; }

ToolRole parse_role(const Reader& r, const YAML::Node& n, const std::string& key, std::set<std::string> extra_keys = {}) {
  std::set<std::string> known = {"name", "stale_after_ms"};
  known.insert(extra_keys.begin(), extra_keys.end());
  r.only(n, key, known);
  ToolRole role;
  if (!n["name"]) r.fail(n, key + ".name", "missing: the appliance's tool name (its poses arrive on ARNAV_POSE_<name>)");
  role.name = r.text(n, key, "name", "");
  if (role.name.empty()) r.fail(n["name"], key + ".name", "must not be empty");
  role.stale_after_ms = r.number(n, key, "stale_after_ms", role.stale_after_ms, 1.0, 60000.0);
  return role;
}

Eigen::Vector3d vec3(const Reader& r, const YAML::Node& n, const std::string& key) {
  const auto v = r.numbers(n, key);
  if (v.size() != 3) r.fail(n, key, "expected 3 numbers [x, y, z] in mm");
  return {v[0], v[1], v[2]};
}

// inputs.<action>: an input name, or {input: NAME, state_stale_after_ms: MS}.
InputBinding parse_binding(const Reader& r, const YAML::Node& n, const std::string& key) {
  InputBinding b;
  b.line = line_of(n);
  if (n.IsScalar()) {
    b.input = r.get<std::string>(n, key, "an input name (input_event_t.input_name, e.g. pedal_right)");
  } else {
    r.only(n, key, {"input", "state_stale_after_ms"});
    if (!n["input"]) r.fail(n, key + ".input", "missing: the input's name as the appliance publishes it (can.inputs[].name)");
    b.input = r.text(n, key, "input", "");
    b.state_stale_after_ms = r.number(n, key, "state_stale_after_ms", b.state_stale_after_ms, 10.0, 60000.0);
  }
  if (b.input.empty()) r.fail(n, key, "must name an input (e.g. pedal_right)");
  return b;
}

// registration.live.swab: {source: NAME | channel: CH, accept: INPUT, min_points: N, method: rigid, ...}.
SwabRegistrationSettings parse_swab(const Reader& r, const YAML::Node& n) {
  const std::string key = "registration.live.swab";
  if (!n.IsMap())
    r.fail(n, key, "expected a map, e.g. {source: pointer, accept: pedal_accept, min_points: 150, method: rigid}");
  r.only(n, key, {"source", "channel", "accept", "min_points", "method", "min_extent_mm", "max_reference_motion_mm", "max_change_mm",
                  "max_change_deg"});
  SwabRegistrationSettings s;
  s.line = line_of(n);
  if (n["source"] && n["channel"]) r.fail(n["channel"], key + ".channel", "give source (channel ARNAV_CLOUD_<source>) or channel, not both");
  if (n["source"]) {
    const std::string src = r.text(n, key, "source", "");
    if (src.empty()) r.fail(n["source"], key + ".source", "must name the appliance's swab source (its swab.source, e.g. pointer)");
    s.channel = "ARNAV_CLOUD_" + src;
  }
  if (n["channel"]) {
    s.channel = r.text(n, key, "channel", "");
    if (s.channel.empty()) r.fail(n["channel"], key + ".channel", "must name an LCM channel (e.g. ARNAV_CLOUD_pointer)");
  }
  s.accept_input = r.text(n, key, "accept", "");
  s.min_points = r.integer(n, key, "min_points", s.min_points, 10, 1000000);
  s.method = r.text(n, key, "method", s.method);
  if (s.method == "nonrigid")
    r.fail(n["method"], key + ".method",
           "'nonrigid' is not available in arnav-host: the session's tissue model cannot start from a registered shape yet; "
           "use 'rigid' here (surface ICP) and arnav-register --lcm for the non-rigid fit (docs/register.md)");
  if (s.method != "rigid") r.fail(n["method"], key + ".method", "must be 'rigid' (point-to-plane ICP from the landmark or prior pose)");
  s.min_extent_mm = r.number(n, key, "min_extent_mm", s.min_extent_mm, 1.0, 1000.0);
  s.max_reference_motion_mm = r.number(n, key, "max_reference_motion_mm", s.max_reference_motion_mm, 0.01, 100.0);
  s.max_change_mm = r.number(n, key, "max_change_mm", s.max_change_mm, 0.1, 1000.0);
  s.max_change_deg = r.number(n, key, "max_change_deg", s.max_change_deg, 0.1, 180.0);
  return s;
}

LiveRegistrationSettings parse_live(const Reader& r, const YAML::Node& n, const std::string& base_dir) {
  const std::string key = "registration.live";
  r.only(n, key, {"landmarks", "pointer", "accept", "tip_mm", "window_ms", "max_motion_mm", "stale_after_ms", "fle_mm", "swab",
                  "initial_pose"});
  LiveRegistrationSettings l;
  l.line = line_of(n);
  if (n["swab"]) l.swab = parse_swab(r, n["swab"]);
  if (n["initial_pose"]) {
    if (n["landmarks"])
      r.fail(n["initial_pose"], key + ".initial_pose", "give landmarks (touched with the pointer) or initial_pose (a prior X_RefModel file), not both");
    if (!l.swab)
      r.fail(n["initial_pose"], key + ".initial_pose",
             "initial_pose is refined by a surface swab: add swab: {source: pointer, accept: INPUT} (or use registration: FILE)");
    l.initial_pose_path = resolve(base_dir, r.text(n, key, "initial_pose", ""));
    try {
      l.X_RefModel_initial = calib::read_transform(l.initial_pose_path, "X_RefModel").X_ParentChild;
    } catch (const calib::CalibError& e) {
      r.fail(n["initial_pose"], key + ".initial_pose", std::string(e.what()) + " (a rigid transform file named X_RefModel: parent_frame Ref, child_frame Model)");
    }
    if (n["pointer"]) l.pointer = r.text(n, key, "pointer", "");
    l.accept_input = r.text(n, key, "accept", "");
    return l;
  }
  if (!n["landmarks"])
    r.fail(n, key + ".landmarks", "missing: a CSV of model-frame landmarks (name,x_mm,y_mm,z_mm; at least 3), or initial_pose: FILE with swab:");
  l.landmarks_path = resolve(base_dir, r.text(n, key, "landmarks", ""));
  try {
    for (const auto& p : read_targets(l.landmarks_path)) l.landmarks_Model_mm.emplace_back(p.name, p.p_mm);
  } catch (const LoadError& e) {
    r.fail(n["landmarks"], key + ".landmarks", e.what());
  }
  if (l.landmarks_Model_mm.size() < 3)
    r.fail(n["landmarks"], key + ".landmarks", l.landmarks_path + " has " + std::to_string(l.landmarks_Model_mm.size()) +
                                                   " landmark(s): paired-point registration needs at least 3 (not collinear)");
  if (!n["pointer"]) r.fail(n, key + ".pointer", "missing: the pointer's tool name (its poses arrive on ARNAV_POSE_<name>)");
  l.pointer = r.text(n, key, "pointer", "");
  if (n["tip_mm"]) l.tip_Tool_mm = vec3(r, n["tip_mm"], key + ".tip_mm");
  l.accept_input = r.text(n, key, "accept", "");
  l.window_ms = r.number(n, key, "window_ms", l.window_ms, 0.0, 5000.0);
  l.max_motion_mm = r.number(n, key, "max_motion_mm", l.max_motion_mm, 0.01, 100.0);
  l.stale_after_ms = r.number(n, key, "stale_after_ms", l.stale_after_ms, 1.0, 60000.0);
  l.fle_mm = r.number(n, key, "fle_mm", l.fle_mm, 0.0, 100.0);
  return l;
}

// tools.grasper: {name, stale_after_ms, tip_mm, radius_mm, stiffness_mN_per_mm,
// grasp: {input: NAME [, state_stale_after_ms: MS]} | {always: true}}.
GrasperRole parse_grasper(const Reader& r, const YAML::Node& n) {
  const std::string key = "tools.grasper";
  GrasperRole g;
  static_cast<ToolRole&>(g) = parse_role(r, n, key, {"tip_mm", "grasp", "radius_mm", "stiffness_mN_per_mm"});
  g.line = line_of(n);
  if (n["tip_mm"]) g.tip_Tool_mm = vec3(r, n["tip_mm"], key + ".tip_mm");
  if (!n["radius_mm"]) r.fail(n, key + ".radius_mm", "missing: surface vertices within this distance of the tip (mm) are grasped");
  g.radius_mm = r.number(n, key, "radius_mm", g.radius_mm, 0.1, 100.0);
  g.stiffness_mN_per_mm = r.number(n, key, "stiffness_mN_per_mm", g.stiffness_mN_per_mm, 1e-3, 1e6);
  const YAML::Node grasp = n["grasp"];
  if (!grasp || !grasp.IsMap())
    r.fail(grasp ? grasp : n, key + ".grasp", "missing: when the grasper holds the tissue, {input: <input name>} (while held) or {always: true}");
  if (grasp["always"]) {
    r.only(grasp, key + ".grasp", {"always"});
    g.grasp_always = r.boolean(grasp, key + ".grasp", "always", false);
    if (!g.grasp_always) r.fail(grasp["always"], key + ".grasp.always", "must be true, or give {input: <input name>} instead");
  } else {
    g.grasp_input = parse_binding(r, grasp, key + ".grasp");
  }
  return g;
}

}  // namespace

SessionConfig parse_session(const std::string& text, const std::string& source, const std::string& base_dir) {
  const Reader r(source);
  const YAML::Node root = r.load_root(text);
  r.only(root, "", {"arnav_session_version", "lcm_url", "stale_after_ms", "print_period_s", "scene", "registration", "tools",
                    "camera", "model", "overlay", "record", "inputs", "cutting", "display", "security", "surfaces"});
  SessionConfig c;
  c.source = source;
  try {  // `security:` (docs/protocol.md, "Sealed bus"); the key is loaded when the bus opens
    c.security = seal::parse_security(root["security"], source, base_dir);
  } catch (const seal::SecurityError& e) {
    throw SessionError(e.what());
  }
  if (!root["arnav_session_version"]) r.fail(root, "arnav_session_version", "missing: add 'arnav_session_version: 1' at the top");
  if (r.integer(root, "", "arnav_session_version", 1, 1, 1000) != 1)
    r.fail(root["arnav_session_version"], "arnav_session_version", "this arnav-host reads version 1");
  c.lcm_url = r.text(root, "", "lcm_url", c.lcm_url);
  c.stale_after_ms = r.number(root, "", "stale_after_ms", c.stale_after_ms, 1.0, 600000.0);
  c.print_period_s = r.number(root, "", "print_period_s", c.print_period_s, 0.05, 3600.0);

  if (const YAML::Node tools = root["tools"]) {
    r.only(tools, "tools", {"reference", "scalpel", "pointer", "grasper"});
    if (tools["grasper"]) c.grasper = parse_grasper(r, tools["grasper"]);
    if (tools["reference"]) c.reference = parse_role(r, tools["reference"], "tools.reference");
    if (tools["pointer"]) c.pointer = parse_role(r, tools["pointer"], "tools.pointer");
    if (const YAML::Node s = tools["scalpel"]) {
      ScalpelRole scalpel;
      static_cast<ToolRole&>(scalpel) = parse_role(r, s, "tools.scalpel", {"blade"});
      const YAML::Node blade = s["blade"];
      if (!blade) r.fail(s, "tools.scalpel.blade", "missing: the cutting edge in the tool frame, {tip_mm: [x, y, z], heel_mm: [x, y, z]}");
      r.only(blade, "tools.scalpel.blade", {"tip_mm", "heel_mm"});
      if (!blade["tip_mm"] || !blade["heel_mm"]) r.fail(blade, "tools.scalpel.blade", "needs both tip_mm and heel_mm");
      scalpel.tip_Tool_mm = vec3(r, blade["tip_mm"], "tools.scalpel.blade.tip_mm");
      scalpel.heel_Tool_mm = vec3(r, blade["heel_mm"], "tools.scalpel.blade.heel_mm");
      if ((scalpel.tip_Tool_mm - scalpel.heel_Tool_mm).norm() < 1.0)
        r.fail(blade, "tools.scalpel.blade", "tip and heel are less than 1 mm apart");
      c.scalpel = scalpel;
    }
  }

  if (const YAML::Node scene = root["scene"]) {
    c.scene_path = resolve(base_dir, r.text(root, "", "scene", ""));
    c.scene_line = line_of(scene);
    if (!std::filesystem::exists(*c.scene_path)) r.fail(scene, "scene", "file " + *c.scene_path + " not found");
  }
  if (const YAML::Node reg = root["registration"]) {
    if (reg.IsMap()) {
      r.only(reg, "registration", {"live"});
      if (!reg["live"]) r.fail(reg, "registration", "give a file (registration: X_RefModel.yaml) or live: {landmarks: FILE, pointer: TOOL, accept: INPUT}");
      c.live_registration = parse_live(r, reg["live"], base_dir);
    } else {
      c.registration_path = resolve(base_dir, r.text(root, "", "registration", ""));
      try {
        const auto record = calib::read_transform(c.registration_path, "X_RefModel");
        c.X_RefModel = record.X_ParentChild;
      } catch (const calib::CalibError& e) {
        r.fail(reg, "registration", std::string(e.what()) + " (a rigid transform file named X_RefModel: parent_frame Ref, child_frame Model)");
      }
    }
  }

  if (const YAML::Node in = root["inputs"]) {
    r.only(in, "inputs", {"cut_enable", "accept"});
    if (in["cut_enable"]) c.inputs.cut_enable = parse_binding(r, in["cut_enable"], "inputs.cut_enable");
    if (in["accept"]) c.inputs.accept = parse_binding(r, in["accept"], "inputs.accept");
  }
  if (const YAML::Node cut = root["cutting"]) {
    r.only(cut, "cutting", {"mode"});
    c.cutting.line = line_of(cut);
    c.cutting.mode = r.text(cut, "cutting", "mode", "");
    if (c.cutting.mode != "input" && c.cutting.mode != "always" && c.cutting.mode != "off")
      r.fail(cut["mode"] ? cut["mode"] : cut, "cutting.mode",
             "must be 'input' (cut while inputs.cut_enable is held), 'always' (whenever the blade is tracked) or 'off' (the blade only pushes)");
    if (c.cutting.mode == "input" && !c.inputs.cut_enable)
      r.fail(cut["mode"], "cutting.mode", "'input' needs inputs.cut_enable: <input name> (e.g. pedal_right)");
  } else if (c.inputs.cut_enable) {
    c.cutting.mode = "input";
  }
  if (c.live_registration) {
    LiveRegistrationSettings& l = *c.live_registration;
    const YAML::Node live = root["registration"]["live"];
    if (l.accept_input.empty() && c.inputs.accept) l.accept_input = c.inputs.accept->input;
    if (l.accept_input.empty() && !l.X_RefModel_initial)
      r.fail(live, "registration.live.accept", "missing: the input whose press takes a landmark (accept: button_1, or inputs.accept)");
    if (l.swab && l.swab->accept_input.empty()) {
      if (l.accept_input.empty())
        r.fail(live["swab"], "registration.live.swab.accept", "missing: the input whose press registers the swab (accept: pedal_accept, or inputs.accept)");
      l.swab->accept_input = l.accept_input;
    }
    if (c.pointer && c.pointer->name == l.pointer) l.stale_after_ms = std::min(l.stale_after_ms, c.pointer->stale_after_ms);
  }

  if (const YAML::Node cam = root["camera"]) {
    r.only(cam, "camera", {"name", "intrinsics", "pose_from", "pose_tool", "hand_eye", "stale_after_ms"});
    CameraSettings s;
    if (!cam["name"]) r.fail(cam, "camera.name", "missing: the appliance's camera name (frames arrive on ARNAV_FRAME_<name>)");
    s.name = r.text(cam, "camera", "name", "");
    if (!cam["intrinsics"]) r.fail(cam, "camera.intrinsics", "missing: the camera's intrinsics file (arnav-calib intrinsics)");
    s.intrinsics_path = resolve(base_dir, r.text(cam, "camera", "intrinsics", ""));
    try {
      s.intrinsics = calib::read_intrinsics(s.intrinsics_path);
    } catch (const calib::CalibError& e) {
      r.fail(cam["intrinsics"], "camera.intrinsics", e.what());
    }
    s.pose_from = r.text(cam, "camera", "pose_from", s.pose_from);
    if (s.pose_from != "reference" && s.pose_from != "tool")
      r.fail(cam["pose_from"], "camera.pose_from", "must be 'reference' (the reference tool is measured in Cam) or 'tool' (tracked camera marker + hand_eye)");
    if (s.pose_from == "tool") {
      if (!cam["pose_tool"] || !cam["hand_eye"])
        r.fail(cam, "camera", "pose_from: tool needs pose_tool (the camera marker's tool name) and hand_eye (X_<Tool>Cam file)");
      s.pose_tool = r.text(cam, "camera", "pose_tool", "");
      s.hand_eye_path = resolve(base_dir, r.text(cam, "camera", "hand_eye", ""));
      try {
        const auto rec = calib::read_transform(s.hand_eye_path);
        if (rec.child_frame == "Cam")
          s.X_ToolCam = rec.X_ParentChild;
        else if (rec.parent_frame == "Cam")
          s.X_ToolCam = rec.X_ParentChild.inverse();
        else
          r.fail(cam["hand_eye"], "camera.hand_eye", rec.name() + " does not involve frame Cam: give X_<Tool>Cam or X_Cam<Tool>");
      } catch (const calib::CalibError& e) {
        r.fail(cam["hand_eye"], "camera.hand_eye", e.what());
      }
    } else if (cam["pose_tool"] || cam["hand_eye"]) {
      r.fail(cam, "camera", "pose_tool and hand_eye belong to pose_from: tool");
    }
    s.stale_after_ms = r.number(cam, "camera", "stale_after_ms", s.stale_after_ms, 1.0, 60000.0);
    c.camera = s;
  }

  if (const YAML::Node m = root["model"]) {
    r.only(m, "model", {"rate_hz", "gravity", "nice", "cpu_partition", "input_wait_ms", "cut_catch_up_ms"});
    c.model.rate_hz = r.number(m, "model", "rate_hz", c.model.rate_hz, 1.0, 1000.0);
    c.model.input_wait_ms = r.number(m, "model", "input_wait_ms", c.model.input_wait_ms, 0.0, 10000.0);
    c.model.cut_catch_up_ms = r.number(m, "model", "cut_catch_up_ms", c.model.cut_catch_up_ms, 0.0, 60000.0);
    c.model.gravity = r.boolean(m, "model", "gravity", c.model.gravity);
    if (m["nice"]) c.model.nice = r.integer(m, "model", "nice", 5, -20, 19);
    c.model.cpu_partition = r.text(m, "model", "cpu_partition", c.model.cpu_partition);
    c.model.cpu_partition_line = line_of(m["cpu_partition"]);
    if (c.model.cpu_partition != "auto" && c.model.cpu_partition != "on" && c.model.cpu_partition != "off")
      r.fail(m["cpu_partition"], "model.cpu_partition",
             "must be 'auto' (a core of its own for the model when there is an overlay), 'on' or 'off' (the scheduler places the threads)");
  }
  if (const YAML::Node d = root["display"]) {
    r.only(d, "display", {"window", "title"});
    c.display.window = r.boolean(d, "display", "window", c.display.window);
    c.display.title = r.text(d, "display", "title", c.display.title);
    c.display.line = line_of(d);
  }
  if (const YAML::Node o = root["overlay"]) {
    r.only(o, "overlay", {"margin_mm", "warn_mm", "msaa", "layers"});
    c.overlay.margin_mm = r.number(o, "overlay", "margin_mm", c.overlay.margin_mm, 0.0, 50.0);
    c.overlay.warn_mm = r.number(o, "overlay", "warn_mm", c.overlay.warn_mm, 0.0, 100.0);
    c.overlay.msaa = r.integer(o, "overlay", "msaa", c.overlay.msaa, 0, 16);
    if (o["layers"]) {
      c.overlay.layers = r.strings(o["layers"], "overlay.layers");
      const std::set<std::string> known = {"tumour", "margin", "vessels", "cut", "organ", "outline", "scalpel"};
      for (std::size_t i = 0; i < c.overlay.layers.size(); ++i)
        if (!known.count(c.overlay.layers[i]))
          r.fail(o["layers"][i], "overlay.layers[" + std::to_string(i) + "]",
                 "unknown layer '" + c.overlay.layers[i] + "' (known: tumour, margin, vessels, cut, organ, outline, scalpel)");
    }
  }
  if (const YAML::Node rec = root["record"]) {
    r.only(rec, "record", {"video_fps", "contact_sheet_frames", "contact_sheet_every_s"});
    c.record.video_fps = r.number(rec, "record", "video_fps", c.record.video_fps, 1.0, 240.0);
    c.record.contact_sheet_frames = r.integer(rec, "record", "contact_sheet_frames", c.record.contact_sheet_frames, 1, 100);
    c.record.contact_sheet_every_s = r.number(rec, "record", "contact_sheet_every_s", c.record.contact_sheet_every_s, 0.01, 3600.0);
  }

  if (const YAML::Node s = root["surfaces"]) {
    r.only(s, "surfaces", {"publish_rate_hz"});
    c.surfaces.publish_rate_hz = r.number(s, "surfaces", "publish_rate_hz", c.surfaces.publish_rate_hz, 0.0, 1000.0);
  }

  // What depends on what: the overlay needs a scene, a registration and a reference.
  if (c.camera) {
    if (!c.scene_path) r.fail(root["camera"], "camera", "the overlay needs a scene: add 'scene: <file>.scene.yaml'");
    if (!c.X_RefModel && !c.live_registration)
      r.fail(root["camera"], "camera",
             "the overlay needs a registration: add 'registration: X_RefModel.yaml' or 'registration: {live: {landmarks: FILE, pointer: TOOL, accept: INPUT}}'");
    if (!c.reference) r.fail(root["camera"], "camera", "the overlay needs tools.reference (the patient reference tool)");
  }
  if (c.display.window && !c.camera)
    r.fail(root["display"], "display.window", "a window shows the overlay: it needs a camera (camera: ...); remove display.window or add the camera");
  if (c.scalpel && !c.reference) r.fail(root["tools"]["scalpel"], "tools.scalpel", "a scalpel needs tools.reference (its pose is taken relative to it)");
  if ((c.X_RefModel || c.live_registration) && !c.scene_path)
    r.fail(root["registration"], "registration", "a registration needs a scene (scene: <file>)");
  if (c.live_registration && !c.reference)
    r.fail(root["registration"], "registration.live", "live registration needs tools.reference (the landmarks are taken in its frame)");
  if (c.grasper && !c.scene_path) r.fail(root["tools"]["grasper"], "tools.grasper", "a grasper needs a scene (scene: <file>): it deforms the tissue model");
  if (c.grasper && !c.reference) r.fail(root["tools"]["grasper"], "tools.grasper", "a grasper needs tools.reference (its pose is taken relative to it)");
  if (c.grasper && !c.X_RefModel && !c.live_registration)
    r.fail(root["tools"]["grasper"], "tools.grasper", "a grasper needs a registration (registration: X_RefModel.yaml or {live: ...})");
  if (root["cutting"] && !c.scalpel) r.fail(root["cutting"], "cutting", "cutting needs tools.scalpel (with its blade)");
  if (c.inputs.cut_enable && !c.scalpel) r.fail(root["inputs"]["cut_enable"], "inputs.cut_enable", "cut_enable needs tools.scalpel (with its blade)");
  return c;
}

SessionConfig load_session(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw SessionError(path + ": cannot read the session file (check the path)");
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string base = std::filesystem::path(path).parent_path().string();
  return parse_session(ss.str(), path, base.empty() ? "." : base);
}

}  // namespace arnav::host
