#pragma once
// The tissue model of a navigation session, stepped at its own rate: on its own thread
// (live sessions) or by the caller (replay, deterministic). After every step it publishes
// an immutable snapshot of what the overlay draws (organ surface, tumours and their margin
// shells, vessel centerlines), all in Model (the scene frame, mm).
//
// Inputs and clock (host/app/model_input_clock.hpp): the scalpel's blade samples and the
// grasper's commands are handed in with the device time the tracker measured them
// (push_blade, push_grasp); the model steps on a grid of device times and each step takes
// the samples measured by its time, every blade sample applied on its own. So the model's
// result depends on what the tracker measured, not on when this thread ran.
//
// Cutting (the scene declares `cutting:` and the session has a scalpel): the model is a
// host/cut CutSession (make_cut_session). Each blade sample in Model carries whether cutting
// was enabled (pedal held) at its time; it is applied before the step (cutting: the swept
// surface cuts the volume; not cutting: the blade pushes the tissue). A step without a new
// sample holds the last blade where it was while it is fresh (the tissue may move across
// it). The snapshot then draws the cut volume's boundary as the organ, the cut faces as
// ModelSnapshot::cut_surface, and carries cut statistics and margin/vessel events. A blade
// that was missing (scalpel stale or lost) only re-places itself on its first sample back,
// so a tracking gap never sweeps a cut across the organ.
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <atomic>
#include <condition_variable>
#include <deque>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include "host/app/grasp_coupling.hpp"
#include "host/app/model_input_clock.hpp"
#include "host/cut/cut_session.hpp"
#include "host/cut/material_path.hpp"
#include "host/scene/scene.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host {

struct ModelSnapshot {
  std::int64_t step = 0;
  std::int64_t step_done_mono_us = 0;   // session clock the step was run at (advance_to's now, taken before it ran)
  std::int64_t step_device_time_us = -1;  // the step's time on the device clock (-1: the rest state)
  double step_ms = 0.0;                 // wall time of the step
  bool healthy = true;
  std::string warning;
  TriMesh organ;
  std::vector<TriMesh> tumours;
  std::vector<TriMesh> margins;
  std::vector<Eigen::Vector3d> tumour_centroids_mm;
  std::optional<VesselTree> vessels;
  std::optional<TriMesh> cut_surface;   // filled by the cutting stage (host/cut) when it exists
  Eigen::Matrix3Xd volume_positions_World_mm; // the tet mesh's vertices (carries the cut trace)
  // Cutting only:
  bool cutting = false;                 // the model is a cut session
  int cut_faces = 0;                    // cut faces on the boundary (both sides of every cut)
  std::vector<std::array<Eigen::Vector3d, 2>> cut_rim_mm;  // where the cut meets the organ surface (segments)
  double cut_area_mm2 = 0.0;            // area of the cut (half the cut faces' area)
  std::int64_t events_total = 0;        // margin/vessel events so far (ModelRunner::events())
  std::int64_t cut_steps_total = 0;     // steps that cut (topology changed)
  // Grasper sessions: the device time (appliance clock) of the grasper pose this step used.
  std::int64_t grasper_device_time_us = -1;
  ModelClockCounters clock;             // the input clock's counters after this step
};

// A margin/vessel event raised by the cut session, with the model step it came from.
struct ModelCutEvent {
  std::int64_t step = 0;
  std::int64_t step_done_mono_us = 0;
  cut::CutEvent event;
};

// Per step that put vertices on the cut (split points, vertices snapped or moved onto it):
// the cut-path error, the largest distance of those vertices from the surfaces the blade
// swept while cutting, both in the material (rest) frame: each frame's swept surface (its
// start carried with the tissue, as the cutter used it) is pulled back into the rest
// configuration at the instant of the sweep through the tets holding it; a vertex's rest
// position is where in the material the cut put it. So the tissue's motion after the cut
// (the grasper pulling, the cut opening, the piece inside a ring moving once cut round)
// does not count as path error, and a cut put where the blade was not does. Measured here
// from the mesh and the blade, independently of the cutter's own bookkeeping
// (CutStepReport::max_path_deviation_mm, kept as cutter_path_error_mm).
struct CutStepRecord {
  std::int64_t step = 0;
  double path_error_mm = 0.0;
  int new_cut_vertices = 0;
  double cutter_path_error_mm = 0.0;
  double update_ms = 0.0;
  double rebuild_ms = 0.0;
  int tets_cut = 0;
};

// How long a step waits for late inputs, how far behind the model may fall before it skips
// grid steps (model_input_clock.hpp), and how old the last blade sample may be for a step
// without a new one to hold it.
struct ModelClockSettings {
  double input_wait_ms = 500.0;
  double catch_up_ms = 1000.0;
  double cut_catch_up_ms = 5000.0;  // a stroke in progress holds steps from being skipped up to this far behind
  double blade_stale_ms = 100.0;
  double tool_gap_ms = 100.0;   // the tracker going on this long without a tool's pose: not waited for
};

class ModelRunner {
 public:
  // Builds the scene's tissue model (gravity per `gravity`). `nice` sets the model thread's
  // scheduling priority (Linux nice, per thread: > 0 lower, < 0 higher, which needs
  // CAP_SYS_NICE: refused, nice_error() says so). Throws std::invalid_argument.
  ModelRunner(const Scene& scene, double rate_hz, bool gravity, double margin_mm, int nice = 0,
              std::optional<cut::CutSessionSettings> cutting = std::nullopt, const ModelClockSettings& clock = {});
  ~ModelRunner();
  ModelRunner(const ModelRunner&) = delete;
  ModelRunner& operator=(const ModelRunner&) = delete;

  // Live: the model thread (and the threads it starts) only on these CPUs (empty: any);
  // before start(). host/app/cpu_partition.hpp.
  void set_cpus(const std::vector<int>& cpus) { cpus_ = cpus; }
  // Why the model thread could not be pinned (empty: it was, or no CPUs were given).
  std::string pin_error() const;
  // Live: steps on a thread every 1/rate_hz until stop().
  void start();
  void stop();
  // Unthreaded (replay, tests): performs the steps due at now_us (session clock), at most max_steps.
  int advance_to(std::int64_t now_us, int max_steps = 1000);

  bool cutting() const { return cut_ != nullptr; }
  // A cutting model driven by a scalpel: its blade samples, in the order the tracker
  // measured them (now_us: the session clock at arrival). Call expect_blade() before start().
  void expect_blade();
  void push_blade(const BladeSample& sample, std::int64_t now_us);
  // A tracked grasper coupled to the model (host/app/grasp_coupling.hpp), also on a cutting
  // model (its springs kept through cuts and rebuilds, applied after the blade). push_grasper
  // hands in its pose and request as of a tracker frame; the model thread grasps, follows or
  // releases before each step with the newest measured by the step's time.
  void enable_grasper(const GrasperRole& role);
  void push_grasp(const GraspSample& sample, std::int64_t now_us);
  // The tracker reached device_time_us (another tool's pose; in the order handed to the model).
  void tracker_at(std::int64_t device_time_us, std::int64_t now_us);
  bool has_grasper() const { return grasp_ != nullptr; }
  int nice() const { return nice_; }  // the model thread's nice level asked for (live)
  std::string nice_error() const;     // why that level was refused; empty when in effect
  bool has_inputs() const;
  GraspStatus grasp_status() const;
  ModelClockCounters clock_counters() const;
  // Sessions with inputs: the newest of the last second's snapshots whose step time is no
  // later than device_time_us (a camera frame's capture time, same appliance clock), so a
  // frame is drawn with the model as the tools had it when the image was taken; the oldest
  // kept when none is that old; snapshot() when the model has no inputs.
  std::shared_ptr<const ModelSnapshot> snapshot_at(std::int64_t device_time_us) const;
  // Events and cutting steps from index `from` on (for the rendering thread to consume in order).
  std::vector<ModelCutEvent> events(std::size_t from) const;
  std::vector<CutStepRecord> cut_steps(std::size_t from) const;
  std::shared_ptr<const ModelSnapshot> snapshot() const;
  // Cutting models, after stop() (or unthreaded): every vertex on a cut, where in the
  // material (rest) the cut put it and where it is now (Model, mm); the run's cut, for
  // comparing runs (docs/overlay.md, "Model clock").
  struct CutVertex {
    int id = 0;
    Eigen::Vector3d rest_mm;
    Eigen::Vector3d now_mm;
  };
  std::vector<CutVertex> cut_vertices() const;
  std::int64_t steps() const { return steps_.load(); }
  // Wall times of every step (ms), for the summary.
  std::vector<double> step_times_ms() const;
  // Steps whose warning names the tissue model's step control (issue 29: redone with finer
  // substeps, or at a kept finer factor; host/sim/step_control.hpp).
  std::int64_t step_control_steps() const { return step_control_steps_.load(); }

 private:
  // One step with its inputs (null: the rest state, before the first step).
  void step_once(const ModelStepInputs* in, std::int64_t now_us);
  // The step's blade samples (or the last one held), applied in order; cut statistics and events.
  void apply_blades(const ModelStepInputs& in, std::vector<ModelCutEvent>& events, std::optional<CutStepRecord>& record);
  // True when the gap since the last blade ends the stroke (too long, or the blade back far away).
  bool gap_ends_stroke(const BladeSample& b) const;
  void apply_blade_sample(const BladeSample& b, std::vector<ModelCutEvent>& events, std::optional<CutStepRecord>& record);
  void apply_grasp(GraspBody& body, const ModelStepInputs& in);
  void fill_snapshot(ModelSnapshot& snap);
  const Scene& scene_;
  double rate_hz_;
  double margin_mm_;
  int nice_ = 0;
  std::string nice_error_;
  std::vector<int> cpus_;
  std::string pin_error_;  // mutex_
  std::unique_ptr<TissueModel> model_;
  std::unique_ptr<cut::CutSession> cut_;
  std::unique_ptr<GraspCoupling> grasp_;  // model thread
  GraspCommand grasp_cmd_;                // model thread: the newest taken from the clock
  GraspStatus grasp_status_;              // guarded by mutex_ (copy after each step)
  ModelInputClock clock_;                 // guarded by mutex_
  std::int64_t blade_stale_us_;
  std::int64_t blade_bridge_us_;  // a gap in the blade's samples up to this long does not end the stroke
  std::optional<BladeSample> last_blade_;  // model thread: the newest applied with a blade
  std::deque<std::shared_ptr<const ModelSnapshot>> recent_;  // sessions with inputs: the last second's snapshots (mutex_)
  std::int64_t grasper_device_time_us_ = -1;                 // model thread
  bool blade_gap_ = true;  // no blade applied yet, or it was missing: the next one only places itself
  std::vector<ModelCutEvent> events_;
  std::vector<CutStepRecord> cut_steps_;
  cut::MaterialPathMeter path_meter_;               // the cut-path error in the material (host/cut/material_path.hpp)
  // Cut faces and the cut's rim on the organ surface: found again only when the cut session's
  // boundary changed or vertices were put on the cut (not every step).
  int cut_surface_version_ = -1;
  bool cut_marks_changed_ = false;
  std::vector<std::array<int, 3>> cut_face_tris_;
  std::vector<std::pair<int, int>> cut_rim_;
  mutable std::mutex mutex_;
  std::shared_ptr<const ModelSnapshot> snapshot_;
  std::vector<double> step_ms_;
  std::atomic<std::int64_t> steps_{0};
  std::atomic<std::int64_t> step_control_steps_{0};
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::condition_variable cv_;
};

}  // namespace arnav::host
