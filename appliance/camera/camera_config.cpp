#include "appliance/camera/camera_config.hpp"

#include <yaml-cpp/yaml.h>

#include <cctype>
#include <set>

#include "appliance/markers/calibration_files.hpp"
#include "calibration/lib/rigid_transform_file.hpp"
#include "appliance/markers/tag_family.hpp"
#include "protocol/yaml/yaml_reader.hpp"

namespace arnav::camera {
namespace {

using Reader = yaml::YamlReader<CameraConfigError>;

std::filesystem::path resolve(const std::filesystem::path& base, const std::string& p) {
  const std::filesystem::path path(p);
  return path.is_absolute() ? path : base / path;
}

bool valid_name(const std::string& name) {
  if (name.empty() || name.size() > 64) return false;
  for (char ch : name) {
    if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '-')) return false;
  }
  return true;
}

camera_sim::Trajectory parse_trajectory(const Reader& r, const YAML::Node& n, const std::string& k) {
  camera_sim::Trajectory t;
  if (!n) return t;
  r.only(n, k, {"distance_mm", "amplitude_mm", "offset_mm", "period_s", "tilt_deg", "spin_deg", "phase_s"});
  t.distance_mm = r.number(n, k, "distance_mm", t.distance_mm, 50, 10000);
  if (n["amplitude_mm"]) {
    const auto a = r.numbers(n["amplitude_mm"], k + ".amplitude_mm");
    if (a.size() != 3) r.fail(n["amplitude_mm"], k + ".amplitude_mm", "expected [x, y, z]");
    t.amplitude_mm = Eigen::Vector3d(a[0], a[1], a[2]);
    if (!(std::abs(a[2]) < t.distance_mm - 20)) {
      r.fail(n["amplitude_mm"], k + ".amplitude_mm", "z amplitude must stay 20 mm short of distance_mm");
    }
  }
  if (n["offset_mm"]) {
    const auto o = r.numbers(n["offset_mm"], k + ".offset_mm");
    if (o.size() != 2) r.fail(n["offset_mm"], k + ".offset_mm", "expected [x, y]");
    t.image_offset_mm = Eigen::Vector2d(o[0], o[1]);
  }
  t.period_s = r.number(n, k, "period_s", t.period_s, 0.1, 3600);
  t.tilt_deg = r.number(n, k, "tilt_deg", t.tilt_deg, 0, 80);
  t.spin_deg = r.number(n, k, "spin_deg", t.spin_deg, 0, 180);
  t.phase_s = r.number(n, k, "phase_s", t.phase_s, -3600, 3600);
  return t;
}

}  // namespace

std::optional<CameraConfig> parse_camera_config(const std::string& yaml_text, const std::string& source,
                                                const std::filesystem::path& base_dir) {
  const YAML::Node root = Reader(source).load_root(yaml_text);
  const YAML::Node cam = root["camera"];
  if (!cam) return std::nullopt;
  Reader r(source);
  const std::string P = "camera";
  r.only(cam, P, {"name", "source", "device", "width", "height", "fps", "fourcc", "exposure", "gain", "path", "realtime",
                  "loop", "retry_interval_s", "intrinsics", "detector", "pose", "smoothing", "tools", "publish_frames",
                  "health_rate_hz", "synthetic"});
  CameraConfig c;
  c.source_file = source;
  c.name = r.text(cam, P, "name", c.name);
  if (!valid_name(c.name)) r.fail(cam["name"], P + ".name", "letters, digits, '_' and '-' only (it becomes an LCM channel)");
  const std::string src = r.text(cam, P, "source", "");
  if (src.empty()) r.fail(cam, P + ".source", "missing: v4l2, file, folder or synthetic");
  if (src == "v4l2") c.source = SourceKind::V4l2;
  else if (src == "file") c.source = SourceKind::File;
  else if (src == "folder") c.source = SourceKind::Folder;
  else if (src == "synthetic") c.source = SourceKind::Synthetic;
  else r.fail(cam["source"], P + ".source", "'" + src + "' is not one of v4l2, file, folder, synthetic");

  c.v4l2.device = r.text(cam, P, "device", c.v4l2.device);
  c.v4l2.width = r.integer(cam, P, "width", c.v4l2.width, 16, 8192);
  c.v4l2.height = r.integer(cam, P, "height", c.v4l2.height, 16, 8192);
  c.v4l2.fps = r.number(cam, P, "fps", c.v4l2.fps, 0.1, 1000);
  c.v4l2.fourcc = r.text(cam, P, "fourcc", c.v4l2.fourcc);
  if (!c.v4l2.fourcc.empty() && c.v4l2.fourcc.size() != 4) r.fail(cam["fourcc"], P + ".fourcc", "must have 4 characters, e.g. MJPG or YUYV");
  if (cam["exposure"]) c.v4l2.exposure = r.number(cam, P, "exposure", 0, 1, 100000);
  if (cam["gain"]) c.v4l2.gain = r.number(cam, P, "gain", 0, 0, 10000);
  if (cam["path"]) c.path = resolve(base_dir, r.text(cam, P, "path", ""));
  c.realtime = r.boolean(cam, P, "realtime", c.realtime);
  c.loop = r.boolean(cam, P, "loop", c.loop);
  c.folder_fps = c.realtime && cam["fps"] ? c.v4l2.fps : 0.0;
  c.retry_interval_s = r.number(cam, P, "retry_interval_s", c.retry_interval_s, 0.01, 60);
  c.health_rate_hz = r.number(cam, P, "health_rate_hz", c.health_rate_hz, 0.1, 100);
  if ((c.source == SourceKind::File || c.source == SourceKind::Folder) && c.path.empty()) {
    r.fail(cam, P + ".path", std::string("missing: the ") + (c.source == SourceKind::File ? "video file" : "image folder"));
  }

  // Intrinsics: required for real images; the synthetic camera can make its own.
  if (cam["intrinsics"]) {
    c.intrinsics_file = resolve(base_dir, r.text(cam, P, "intrinsics", ""));
    try {
      c.camera = markers::read_camera(c.intrinsics_file);
    } catch (const std::exception& e) {
      r.fail(cam["intrinsics"], P + ".intrinsics", e.what());
    }
  } else if (c.source != SourceKind::Synthetic) {
    r.fail(cam, P + ".intrinsics", "missing: the camera intrinsics file (`arnav-calib intrinsics` writes camera.yaml)");
  }

  if (const YAML::Node d = cam["detector"]) {
    const std::string k = P + ".detector";
    r.only(d, k, {"family", "decimate", "threads", "sigma", "sharpening", "refine_edges", "max_bits_corrected"});
    c.detector.family = r.text(d, k, "family", c.detector.family);
    try {
      markers::TagFamily check(c.detector.family);
    } catch (const std::invalid_argument& e) {
      r.fail(d["family"], k + ".family", e.what());
    }
    c.detector.decimate = r.number(d, k, "decimate", c.detector.decimate, 1, 8);
    c.detector.threads = r.integer(d, k, "threads", c.detector.threads, 1, 64);
    c.detector.sigma = r.number(d, k, "sigma", c.detector.sigma, 0, 10);
    c.detector.sharpening = r.number(d, k, "sharpening", c.detector.sharpening, 0, 10);
    c.detector.refine_edges = r.boolean(d, k, "refine_edges", c.detector.refine_edges);
    c.detector.max_bits_corrected = r.integer(d, k, "max_bits_corrected", c.detector.max_bits_corrected, 0, 2);
  }
  if (const YAML::Node p = cam["pose"]) {
    const std::string k = P + ".pose";
    r.only(p, k, {"ambiguity_ratio", "ambiguity_min_angle_deg", "max_reprojection_px", "prior_max_age_s"});
    c.pose.ambiguity_ratio = r.number(p, k, "ambiguity_ratio", c.pose.ambiguity_ratio, 1, 100);
    c.pose.ambiguity_min_angle_deg = r.number(p, k, "ambiguity_min_angle_deg", c.pose.ambiguity_min_angle_deg, 0, 90);
    c.pose.max_reprojection_px = r.number(p, k, "max_reprojection_px", c.pose.max_reprojection_px, 0.01, 100);
    c.tracker.prior_max_age_s = r.number(p, k, "prior_max_age_s", c.tracker.prior_max_age_s, 0, 60);
  }
  if (const YAML::Node s = cam["smoothing"]) {
    const std::string k = P + ".smoothing";
    r.only(s, k, {"alpha", "reset_jump_mm", "reset_jump_deg"});
    c.tracker.smoothing_alpha = r.number(s, k, "alpha", c.tracker.smoothing_alpha, 0.01, 1);
    c.tracker.reset_jump_mm = r.number(s, k, "reset_jump_mm", c.tracker.reset_jump_mm, 0.1, 1000);
    c.tracker.reset_jump_deg = r.number(s, k, "reset_jump_deg", c.tracker.reset_jump_deg, 0.1, 180);
  }
  if (const YAML::Node f = cam["publish_frames"]) {
    const std::string k = P + ".publish_frames";
    r.only(f, k, {"enabled", "every", "jpeg_quality", "max_width"});
    c.publish_frames.enabled = r.boolean(f, k, "enabled", true);
    c.publish_frames.every = r.integer(f, k, "every", c.publish_frames.every, 1, 1000);
    c.publish_frames.jpeg_quality = r.integer(f, k, "jpeg_quality", c.publish_frames.jpeg_quality, 10, 100);
    c.publish_frames.max_width = r.integer(f, k, "max_width", c.publish_frames.max_width, 64, 8192);
  }

  const YAML::Node tools = cam["tools"];
  if (!tools) r.fail(cam, P + ".tools", "missing: list the tracked boards/tags, each {name, board: FILE} or {name, tag: {id, size_mm}}");
  if (!tools.IsSequence() || tools.size() == 0) r.fail(tools, P + ".tools", "expected a non-empty list");
  std::set<std::string> names;
  std::set<int> ids;
  for (std::size_t i = 0; i < tools.size(); ++i) {
    const std::string k = P + ".tools[" + std::to_string(i) + "]";
    const YAML::Node t = tools[i];
    r.only(t, k, {"name", "board", "tag"});
    const std::string name = r.text(t, k, "name", "");
    if (!valid_name(name)) r.fail(t["name"] ? t["name"] : t, k + ".name", "missing or not letters, digits, '_' and '-'");
    if (!names.insert(name).second) r.fail(t["name"], k + ".name", "'" + name + "' appears twice");
    ToolConfig tool;
    if (t["board"] && t["tag"]) r.fail(t, k, "give either 'board' or 'tag', not both");
    if (t["board"]) {
      const auto file = resolve(base_dir, r.text(t, k, "board", ""));
      try {
        tool.board = markers::read_board(file, name);
      } catch (const std::exception& e) {
        r.fail(t["board"], k + ".board", e.what());
      }
      if (tool.board.family != c.detector.family) {
        r.fail(t["board"], k + ".board", "board uses family " + tool.board.family + " but camera.detector.family is " +
                                             c.detector.family + " (one detector family per camera)");
      }
    } else if (const YAML::Node tag = t["tag"]) {
      r.only(tag, k + ".tag", {"id", "size_mm"});
      if (!tag["id"] || !tag["size_mm"]) r.fail(tag, k + ".tag", "needs id and size_mm (black border edge)");
      markers::TagFamily fam(c.detector.family);
      const int id = r.integer(tag, k + ".tag", "id", 0, 0, fam.code_count() - 1);
      const double size = r.number(tag, k + ".tag", "size_mm", 0, 1, 2000);
      tool.board = markers::single_tag_board(name, c.detector.family, id, size);
    } else {
      r.fail(t, k, "needs 'board: <layout file>' or 'tag: {id, size_mm}'");
    }
    for (const auto& bt : tool.board.tags) {
      if (!ids.insert(bt.id).second) {
        r.fail(t, k, "tag id " + std::to_string(bt.id) + " is used by two tools (a tag must belong to one tool)");
      }
    }
    tool.tool_id = tool.board.tags.front().id;
    c.tools.push_back(std::move(tool));
  }

  if (c.source == SourceKind::Synthetic) {
    const YAML::Node s = cam["synthetic"];
    const std::string k = P + ".synthetic";
    capture::SyntheticSettings syn;
    if (s) {
      r.only(s, k, {"hfov_deg", "distortion", "frames", "ground_truth", "frames_dir", "noise_sigma", "blur_sigma_px",
                    "lighting", "outage", "boards", "seed", "occluders", "phantom", "readout_ms", "render_ahead_frames",
                    "render_nice", "timing"});
    }
    const YAML::Node none;
    const YAML::Node sn = s ? s : none;
    if (c.intrinsics_file.empty()) {
      syn.camera = markers::pinhole_camera(c.v4l2.width, c.v4l2.height, s ? r.number(sn, k, "hfov_deg", 70, 10, 150) : 70);
      if (s && s["distortion"]) syn.camera.distortion = r.numbers(s["distortion"], k + ".distortion");
      try {
        markers::validate(syn.camera);
      } catch (const std::invalid_argument& e) {
        r.fail(s["distortion"], k + ".distortion", e.what());
      }
      c.camera = syn.camera;
    } else {
      syn.camera = c.camera;
      if (s && (s["hfov_deg"] || s["distortion"])) {
        r.fail(s, k, "hfov_deg/distortion conflict with camera.intrinsics (the synthetic camera uses the intrinsics)");
      }
    }
    syn.fps = c.v4l2.fps;
    syn.realtime = c.realtime;
    if (s) {
      syn.frame_count = static_cast<std::int64_t>(r.integer(sn, k, "frames", 0, 0, 100000000));
      if (s["ground_truth"]) syn.ground_truth_csv = resolve(base_dir, r.text(sn, k, "ground_truth", ""));
      if (s["frames_dir"]) syn.frames_dir = resolve(base_dir, r.text(sn, k, "frames_dir", ""));
      if (s["timing"]) syn.timing_csv = resolve(base_dir, r.text(sn, k, "timing", ""));
      // Sensor readout after the exposure (real time): one frame period unless given.
      if (s["readout_ms"]) syn.readout_s = 1e-3 * r.number(sn, k, "readout_ms", 0, 0, 1000);
      syn.render_ahead_frames = static_cast<int>(r.integer(sn, k, "render_ahead_frames", 2, 1, 16));
      syn.render_nice = static_cast<int>(r.integer(sn, k, "render_nice", 0, -20, 19));
      syn.render.noise_sigma = r.number(sn, k, "noise_sigma", 0, 0, 100);
      syn.render.blur_sigma_px = r.number(sn, k, "blur_sigma_px", 0, 0, 20);
      syn.render.noise_seed = static_cast<std::uint64_t>(r.integer(sn, k, "seed", 1, 0, 1000000000));
      if (const YAML::Node l = s["lighting"]) {
        const std::string kl = k + ".lighting";
        r.only(l, kl, {"gain", "offset", "gradient_per_px", "vignetting"});
        syn.render.lighting.gain = r.number(l, kl, "gain", 1, 0, 10);
        syn.render.lighting.offset = r.number(l, kl, "offset", 0, -255, 255);
        syn.render.lighting.vignetting = r.number(l, kl, "vignetting", 0, 0, 1);
        if (l["gradient_per_px"]) {
          const auto g = r.numbers(l["gradient_per_px"], kl + ".gradient_per_px");
          if (g.size() != 2) r.fail(l["gradient_per_px"], kl + ".gradient_per_px", "expected [gx, gy]");
          syn.render.lighting.gradient_per_px = Eigen::Vector2d(g[0], g[1]);
        }
      }
      if (const YAML::Node occ = s["occluders"]) {
        // Foreground objects (instruments, hands) as image polygons, drawn over the scene.
        if (!occ.IsSequence()) r.fail(occ, k + ".occluders", "expected a list of {polygon_px: [[x, y], ...], reflectance}");
        for (std::size_t i = 0; i < occ.size(); ++i) {
          const std::string ko = k + ".occluders[" + std::to_string(i) + "]";
          r.only(occ[i], ko, {"polygon_px", "reflectance"});
          const YAML::Node poly = occ[i]["polygon_px"];
          if (!poly || !poly.IsSequence() || poly.size() < 3) r.fail(poly ? poly : occ[i], ko + ".polygon_px", "needs at least 3 [x, y] points");
          camera_sim::Occluder o;
          for (std::size_t j = 0; j < poly.size(); ++j) {
            const auto xy = r.numbers(poly[j], ko + ".polygon_px[" + std::to_string(j) + "]");
            if (xy.size() != 2) r.fail(poly[j], ko + ".polygon_px[" + std::to_string(j) + "]", "expected [x, y]");
            o.polygon_px.emplace_back(xy[0], xy[1]);
          }
          o.reflectance = r.number(occ[i], ko, "reflectance", o.reflectance, 0, 1);
          syn.render.occluders.push_back(o);
        }
      }
      if (const YAML::Node o = s["outage"]) {
        r.only(o, k + ".outage", {"at_s", "duration_s"});
        syn.outage_at_s = r.number(o, k + ".outage", "at_s", 0, 0, 1e6);
        syn.outage_duration_s = r.number(o, k + ".outage", "duration_s", 1, 0, 1e6);
      }
    }
    // What moves in front of the camera: by default every tool, one path each.
    const YAML::Node boards = s ? s["boards"] : none;
    if (boards) {
      if (!boards.IsSequence() || boards.size() == 0) r.fail(boards, k + ".boards", "expected a non-empty list of {tool, trajectory}");
      for (std::size_t i = 0; i < boards.size(); ++i) {
        const std::string kb = k + ".boards[" + std::to_string(i) + "]";
        r.only(boards[i], kb, {"tool", "trajectory"});
        const std::string tool = r.text(boards[i], kb, "tool", "");
        const ToolConfig* found = nullptr;
        for (const auto& t : c.tools) {
          if (t.board.name == tool) found = &t;
        }
        if (!found) r.fail(boards[i]["tool"] ? boards[i]["tool"] : boards[i], kb + ".tool", "'" + tool + "' is not in camera.tools");
        syn.boards.push_back({found->board, parse_trajectory(r, boards[i]["trajectory"], kb + ".trajectory")});
      }
    } else {
      for (size_t i = 0; i < c.tools.size(); ++i) {
        camera_sim::Trajectory tr;
        tr.phase_s = 2.5 * static_cast<double>(i);
        tr.image_offset_mm = Eigen::Vector2d(150.0 * (static_cast<double>(i) - 0.5 * static_cast<double>(c.tools.size() - 1)), 0);
        syn.boards.push_back({c.tools[i].board, tr});
      }
    }
    if (const YAML::Node ph = s ? s["phantom"] : none) {
      // A deforming organ phantom (hil_tests' arnav-phantom-record) fixed to one board.
      const std::string kp = k + ".phantom";
      r.only(ph, kp, {"recording", "board", "X_BoardModel", "reflectance", "start_s", "epoch_mono_us"});
      capture::SyntheticPhantom p;
      if (!ph["recording"]) r.fail(ph, kp + ".recording", "missing: the phantom recording file (arnav-phantom-record writes one)");
      const std::filesystem::path rec_path = resolve(base_dir, r.text(ph, kp, "recording", ""));
      try {
        p.recording = std::make_shared<const camera_sim::PhantomRecording>(camera_sim::read_phantom_recording(rec_path));
      } catch (const camera_sim::PhantomError& e) {
        r.fail(ph["recording"], kp + ".recording", e.what());
      }
      const std::string tool = r.text(ph, kp, "board", "");
      bool found = false;
      for (std::size_t i = 0; i < syn.boards.size(); ++i) {
        if (syn.boards[i].board.name == tool) {
          p.board_index = i;
          found = true;
        }
      }
      if (!found) r.fail(ph["board"] ? ph["board"] : ph, kp + ".board", "'" + tool + "' is not a rendered board (camera.tools / synthetic.boards)");
      if (!ph["X_BoardModel"]) r.fail(ph, kp + ".X_BoardModel", "missing: the organ's pose on its board (the host's X_RefModel.yaml)");
      try {
        p.X_BoardModel = calib::read_transform(resolve(base_dir, r.text(ph, kp, "X_BoardModel", ""))).X_ParentChild;
      } catch (const std::exception& e) {
        r.fail(ph["X_BoardModel"], kp + ".X_BoardModel", e.what());
      }
      p.reflectance = r.number(ph, kp, "reflectance", p.reflectance, 0.01, 1);
      p.start_s = r.number(ph, kp, "start_s", 0, -1e6, 1e6);
      if (ph["epoch_mono_us"]) p.epoch_mono_us = static_cast<std::int64_t>(r.number(ph, kp, "epoch_mono_us", 0, 0, 9e15));
      syn.phantom = std::move(p);
    }
    c.synthetic = std::move(syn);
  } else if (cam["synthetic"]) {
    r.fail(cam["synthetic"], P + ".synthetic", "only valid with source: synthetic");
  }
  if (c.source == SourceKind::V4l2 && (c.camera.width != c.v4l2.width || c.camera.height != c.v4l2.height)) {
    r.fail(cam["intrinsics"], P + ".intrinsics",
           "calibrated for " + std::to_string(c.camera.width) + "x" + std::to_string(c.camera.height) + " but camera.width/height ask " +
               std::to_string(c.v4l2.width) + "x" + std::to_string(c.v4l2.height));
  }
  return c;
}

frames::FramesConfig parse_frames_config(const std::string& yaml_text, const std::string& source,
                                         const std::filesystem::path& base_dir) {
  const YAML::Node root = Reader(source).load_root(yaml_text);
  frames::FramesConfig f;
  const YAML::Node n = root["frames"];
  if (!n) return f;
  Reader r(source);
  r.only(n, "frames", {"reference", "reference_tool", "hand_eye", "max_reference_age_s"});
  const std::string ref = r.text(n, "frames", "reference", "Cam");
  try {
    f.reference = frames::parse_reference(ref);
  } catch (const std::invalid_argument& e) {
    r.fail(n["reference"], "frames.reference", e.what());
  }
  f.reference_tool = r.text(n, "frames", "reference_tool", "");
  if (n["hand_eye"]) f.hand_eye = resolve(base_dir, r.text(n, "frames", "hand_eye", ""));
  f.max_reference_age_s = r.number(n, "frames", "max_reference_age_s", f.max_reference_age_s, 0.001, 10);
  // The hand-eye relates the camera to the tracker: only a camera path needs it to put
  // its poses into Ndi or Ref. An NDI-only appliance expresses its poses in Ndi or Ref
  // without one.
  if (f.reference != frames::Reference::Cam && f.hand_eye.empty() && root["camera"]) {
    r.fail(n, "frames.hand_eye",
           "missing: with a camera, reference " + ref + " needs the hand-eye file (X_CamNdi.yaml from `arnav-calib handeye`)");
  }
  if (f.reference == frames::Reference::Ref && f.reference_tool.empty()) {
    r.fail(n, "frames.reference_tool", "missing: the NDI tool that defines frame Ref");
  }
  return f;
}

}  // namespace arnav::camera
