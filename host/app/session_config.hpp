#pragma once
// The navigation session file of `arnav-host SESSION.yaml` (docs/overlay.md): LCM URL,
// which tracked tools play which role, the camera (intrinsics, where its pose comes from),
// the patient scene, the registration and the model/overlay settings. Only what the file
// declares is built: no camera -> no overlay; no scene -> the status monitor only.
// Relative paths are relative to the session file. Every error reads
// "<file>:<line>: key '<key>': <what>" and arnav-host exits 2 on it.
#include <Eigen/Geometry>

#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "calibration/lib/camera_intrinsics.hpp"
#include "protocol/seal/security_config.hpp"

namespace arnav::host {

class SessionError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct ToolRole {
  std::string name;              // the appliance's tool name (ARNAV_POSE_<name>)
  double stale_after_ms = 100.0; // older than this: "stale" banner, its part of the overlay hidden
};

// Blade of the scalpel in its tool frame (Tool), mm: tip and heel of the cutting edge.
struct ScalpelRole : ToolRole {
  Eigen::Vector3d tip_Tool_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d heel_Tool_mm = Eigen::Vector3d(0, 0, 30);
};

struct CameraSettings {
  std::string name;                          // frames arrive on ARNAV_FRAME_<name>
  std::string intrinsics_path;
  calib::CameraIntrinsics intrinsics;
  // Where X_CamRef comes from: "reference": the reference tool's own pose is measured in
  // Cam (its tag board seen by this camera, or the appliance publishing in Cam);
  // "tool": a tracked camera marker (pose_tool) and the hand-eye X_<Tool>Cam.
  std::string pose_from = "reference";
  std::string pose_tool;
  std::string hand_eye_path;
  Eigen::Isometry3d X_ToolCam = Eigen::Isometry3d::Identity();
  double stale_after_ms = 150.0;             // frame gap over this: flag camera_gap, counted; also the camera marker's limit
};

inline constexpr int kModelNice = 5;
inline constexpr int kCuttingModelNice = -5;

struct ModelSettings {
  double rate_hz = 60.0;        // model steps per second on the model thread
  bool gravity = false;         // the scene's gravity; off: the CT shape is already the loaded one
  // The model thread's Linux nice level (0: the rendering thread's priority). Unset:
  // kModelNice (the model yields to rendering) unless the session cuts: then
  // kCuttingModelNice, above the machine's other work, because the cut lands where the
  // blade went only while the model keeps up with the blade (docs/overlay.md, "Threads and
  // cores"; issue 20: beside one busy process per core the model fell 5 s behind during the
  // demo's ring cut at nice 5, and still 5 s at nice 0 with the cut refined ahead of the
  // blade; 1 s at -5). A negative level needs CAP_SYS_NICE (root): refused, the thread
  // keeps the process's level and the summary's model.nice_error says so.
  std::optional<int> nice;
  // Cores: "on": the model thread (and the solver's workers) on a core of its own, the
  // rendering thread and the software rasteriser's threads on the others (docs/overlay.md,
  // "Threads and cores"); "off": the scheduler places them; "auto": on when the session
  // renders an overlay, the process may use 2 or more CPUs and the 1-minute load average
  // at start is below that count (a machine busy with other work: off).
  std::string cpu_partition = "auto";
  int cpu_partition_line = 0;
  // The model steps on the tracker's clock (docs/overlay.md, "Model clock"): a step waits
  // this long (host clock) past its device time for tool poses that are late (the camera's
  // reference, a stalled link) before it runs without them.
  double input_wait_ms = 500.0;
  // A cut stroke in progress is not skipped over when the model thread falls behind (each
  // blade sample meets the tissue as it was then; the model catches up after the stroke)
  // until the model is this far behind; past it, steps are skipped and counted.
  double cut_catch_up_ms = 5000.0;
};

// Where the overlay is shown besides the recording: a window (GLFW) on a workstation's
// display; headless (EGL surfaceless) otherwise, the default for tests and CI.
struct DisplaySettings {
  bool window = false;
  std::string title = "ARNav overlay";
  int line = 0;
};

struct OverlaySettings {
  double margin_mm = 5.0;       // safety margin around each tumour
  double warn_mm = 5.0;         // distance colour: amber below this, red inside the margin
  int msaa = 0;                 // OpenGL multisampling (costly on the software rasteriser)
  std::vector<std::string> layers = {"tumour", "margin", "vessels", "cut", "organ", "outline", "scalpel"};
};

struct RecordSettings {
  double video_fps = 30.0;      // overlay.avi frame rate (the camera's displayed rate)
  int contact_sheet_frames = 12;
  double contact_sheet_every_s = 1.0;
};

// Named inputs of the appliance's CAN path (ARNAV_INPUT changes, ARNAV_INPUT_STATE
// snapshots; input_event_t) bound to session actions (docs/overlay.md, "Inputs").
struct InputBinding {
  std::string input;                  // input_event_t.input_name, e.g. "pedal_right"
  double state_stale_after_ms = 1000; // no change or snapshot seen for this long: treated as released (disarmed)
  int line = 0;
};

struct InputSettings {
  std::optional<InputBinding> cut_enable;  // the scalpel cuts only while this input is held
  std::optional<InputBinding> accept;      // accept a landmark / registration step (press edges)
};

// Cutting in the session (the scene declares `cutting:` and tools.scalpel is set).
struct CuttingSettings {
  // "input": while inputs.cut_enable is held; "always": every frame the blade is tracked;
  // "off": the blade only pushes the tissue. Empty: not given (input when inputs.cut_enable exists).
  std::string mode;
  int line = 0;
};

// Surface swab after the landmark step (or after a prior pose): the appliance's
// point_cloud_t swab messages are collected and, on an accept press, refine the
// registration by point-to-plane ICP (docs/overlay.md, "Swab registration").
struct SwabRegistrationSettings {
  std::string channel = "ARNAV_CLOUD_pointer";  // source: NAME -> ARNAV_CLOUD_NAME, or channel: FULL
  std::string accept_input;            // empty: the live registration's accept input
  int min_points = 100;                // fewer points: the accept press is refused (keep swabbing)
  std::string method = "rigid";        // surface rigid ICP from the landmark (or prior) pose
  double min_extent_mm = 30.0;         // the swab must span at least this (largest bounding-box side)
  double max_reference_motion_mm = 2.0;  // a message not in Ref: refused when the reference moved more over it
  double max_change_mm = 25.0;         // a refinement moving the model further than this (at the target) is refused
  double max_change_deg = 15.0;        // ... or turning it more than this
  int line = 0;
};

// Live paired-point registration with the tracked pointer (docs/overlay.md).
struct LiveRegistrationSettings {
  std::optional<SwabRegistrationSettings> swab;       // live.swab
  std::optional<Eigen::Isometry3d> X_RefModel_initial; // live.initial_pose: a prior pose instead of landmarks (needs swab)
  std::string initial_pose_path;
  std::string landmarks_path;
  std::vector<std::pair<std::string, Eigen::Vector3d>> landmarks_Model_mm;  // in the order they are taken
  std::string pointer;                 // tool name (its tip is the tool origin, mm)
  Eigen::Vector3d tip_Tool_mm = Eigen::Vector3d::Zero();
  std::string accept_input;            // input_event_t.input_name whose press takes a landmark
  double window_ms = 200.0;            // pointer poses averaged over this window before the press
  double max_motion_mm = 1.0;          // refused when the tip moved more than this in the window
  double stale_after_ms = 100.0;       // refused when the newest pointer pose is older
  double fle_mm = 0.35;                // fiducial localisation error (RMS) for the predicted TRE
  int line = 0;
};

// A tracked grasper coupled to the tissue model (docs/overlay.md, "Grasper";
// host/app/grasp_coupling.hpp): while grasping, the organ surface within radius_mm of the
// tip at grasp start follows the tool.
struct GrasperRole : ToolRole {
  Eigen::Vector3d tip_Tool_mm = Eigen::Vector3d::Zero();  // jaws in the tool frame, mm
  std::optional<InputBinding> grasp_input;  // grasp: {input: NAME}: grasps while held
  bool grasp_always = false;                // grasp: {always: true}: grasps whenever tracked and the tip is at the surface
  double radius_mm = 10.0;                  // surface vertices within this of the tip are held
  double stiffness_mN_per_mm = 200.0;       // spring per held vertex
  int line = 0;
};

// The model's surfaces on the bus for other programs (arnav-igtl: POLYDATA for 3D Slicer):
// surface_mesh_t on ARNAV_SURFACE_<name> (host/app/surface_publisher.hpp), live sessions.
struct SurfaceSettings {
  double publish_rate_hz = 10.0;   // 0: not published
};

struct SessionConfig {
  std::string source;                        // the session file
  std::string lcm_url = "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304";
  seal::SecuritySettings security;           // `security:`; arnav-host refuses a live bus or a log without it
  double stale_after_ms = 250.0;             // status table freshness (every tool)
  double print_period_s = 1.0;
  std::optional<std::string> scene_path;
  int scene_line = 0;
  std::optional<Eigen::Isometry3d> X_RefModel;   // registration (Model -> Ref)
  std::string registration_path;
  std::optional<LiveRegistrationSettings> live_registration;  // registration: {live: ...}
  InputSettings inputs;
  CuttingSettings cutting;
  std::optional<ToolRole> reference;
  std::optional<ScalpelRole> scalpel;
  std::optional<ToolRole> pointer;
  std::optional<GrasperRole> grasper;           // tools.grasper
  std::optional<CameraSettings> camera;
  ModelSettings model;
  OverlaySettings overlay;
  RecordSettings record;
  DisplaySettings display;
  SurfaceSettings surfaces;
};

// Reads the file and the files it names (intrinsics, hand-eye, registration; not the
// scene, which load_scene reads). Throws SessionError.
SessionConfig load_session(const std::string& path);
// Same from text; `source` names it in errors, relative paths resolve against base_dir.
SessionConfig parse_session(const std::string& yaml_text, const std::string& source, const std::string& base_dir);

}  // namespace arnav::host
