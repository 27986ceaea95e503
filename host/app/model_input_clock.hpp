#pragma once
// The tissue model's inputs on the device clock (docs/overlay.md, "Model clock").
//
// The scalpel's blade samples (one per tracker frame, in Model, with whether the cut pedal
// was held at that instant) and the grasper's commands are kept in the order the tracker
// measured them (device time: the appliance's CLOCK_MONOTONIC, tool_pose_t.receive_time_mono_us).
// The model steps on a fixed grid of device times t_k = k / rate_hz. Step k takes every blade
// sample measured in (t_(k-1), t_k], each applied on its own (never merged into one chord),
// and the newest grasper command measured by t_k. A step runs once every input stream it
// needs has delivered a sample measured at or after t_k (so the step sees exactly what the
// tracker measured by then, whatever the threads' timing). A stream whose tool the tracker
// stopped reporting (other tools' poses, tracker_at(), have gone on by more than `gap_ms`)
// is not waited for; when every stream is late (tracking lost, cable pulled) the step runs
// once the host clock has passed t_k by `wait_ms`, and the late samples are applied at the
// next step, in order, and counted.
//
// So a session's cut depends on the blade's path and the tissue's state at each blade
// sample, not on when the model thread ran: the same log replayed on an idle or a loaded
// machine gives the same cut, and a live session on a busy machine catches up along the
// blade's real path. More than `catch_up_ms` behind, grid steps are skipped (the tissue
// jumps to where the grasper is now), but never past a blade sample taken while cutting:
// each cutting sample still meets the tissue as it was at its own step, so a late model
// thread cuts where the blade went and catches up once the stroke ends. Only past
// `cut_catch_up_ms` behind (a model far too slow for the machine) are steps skipped during
// a stroke too; the cutting samples that then share a step are counted (cut_samples_merged).
//
// Without input streams (no scalpel on a cutting model, no grasper) the grid runs on the
// host clock alone. Not thread-safe: ModelRunner guards it.
#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <deque>
#include <climits>
#include <optional>
#include <vector>

#include "host/app/grasp_coupling.hpp"

namespace arnav::host {

// The scalpel at one tracker frame.
struct BladeSample {
  std::int64_t device_time_us = 0;
  std::optional<std::array<Eigen::Vector3d, 2>> blade_Model_mm;  // {tip, heel}; nullopt: not tracked (or not registered) then
  bool cutting = false;                                           // the cut pedal held (and fresh) at device_time_us
};

// A grasper command as of one tracker frame (GraspCommand::pose_time_us and device_time_us:
// the device time of the newest valid grasper pose it carries).
struct GraspSample {
  std::int64_t device_time_us = 0;  // the frame's device time (the stream's progress)
  GraspCommand command;
};

struct ModelStepInputs {
  std::int64_t device_time_us = 0;     // t_k
  std::vector<BladeSample> blades;     // measured in (t_(k-1), t_k] (and late ones), oldest first
  std::optional<GraspCommand> grasp;   // the newest measured by t_k (nullopt: none new)
};

struct ModelClockCounters {
  std::int64_t steps = 0;
  std::int64_t steps_waited_out = 0;   // run by the host-clock limit with an input stream late
  std::int64_t steps_skipped = 0;      // grid steps skipped to catch up (the model was too far behind)
  std::int64_t steps_kept_for_cut = 0; // steps run although too far behind: a cutting blade sample was due
  std::int64_t cut_samples_merged = 0; // cutting samples applied in a step that skipped grid steps (past cut_catch_up_ms)
  std::int64_t late_samples = 0;       // samples measured at or before a step already taken
  double max_lag_ms = 0.0;             // largest host-clock lag of a step behind its device time (offset removed)
};

class ModelInputClock {
 public:
  // wait_ms: how long past a step's device time the host waits for a late stream; gap_ms:
  // how far the tracker may go on without a stream's tool before it is not waited for;
  // catch_up_ms: how far behind the grid steps are skipped; cut_catch_up_ms (>= catch_up_ms):
  // how far behind a stroke in progress may hold the model before its steps are skipped too.
  ModelInputClock(double rate_hz, double wait_ms, double catch_up_ms, double gap_ms, double cut_catch_up_ms = 5000.0);
  // The streams the model waits for (a cutting model with a scalpel; a grasper).
  void require_blade() { blade_.required = true; }
  void require_grasp() { grasp_.required = true; }
  bool has_inputs() const { return blade_.required || grasp_.required; }

  // Samples of one stream arrive in device-time order (an older one is accepted and applied
  // at the next step, counted late). host_now_us: the session clock at arrival.
  void push_blade(const BladeSample& s, std::int64_t host_now_us);
  void push_grasp(const GraspSample& s, std::int64_t host_now_us);
  // The tracker (any tool's pose, in the order they are handed to the model) has reached
  // this device time.
  void tracker_at(std::int64_t device_us, std::int64_t host_now_us);

  // The device time of the next step if it may run at host_now_us.
  std::optional<std::int64_t> due(std::int64_t host_now_us);
  // Host time by which the next step runs even if its inputs are late (live thread's sleep).
  std::int64_t deadline_host_us(std::int64_t host_now_us) const;
  // Takes step t's inputs (t from due()) and moves the grid on.
  ModelStepInputs take(std::int64_t t_us, std::int64_t host_now_us);

  const ModelClockCounters& counters() const { return counters_; }
  std::int64_t period_us() const { return period_us_; }

 private:
  struct Stream {
    bool required = false;
    std::int64_t last_device_us = -1;  // newest sample's device time
    std::int64_t last_host_us = -1;    // its arrival (session clock)
  };
  void note(Stream& s, std::int64_t device_us, std::int64_t host_now_us);
  // All samples measured at or before the returned time have arrived (streams silent for
  // longer than wait_ms are not waited for: `silent` says one was left out); nullopt:
  // nothing is known yet.
  std::optional<std::int64_t> complete_through(std::int64_t host_now_us, bool& silent) const;
  void anchor(std::int64_t device_us);
  // The grid step to skip to from step t when the newest complete input is at `newest`.
  std::int64_t skip_target(std::int64_t t, std::int64_t newest);

  std::int64_t period_us_;
  std::int64_t wait_us_;
  std::int64_t catch_up_us_;
  std::int64_t cut_catch_up_us_;
  std::int64_t gap_us_;
  Stream blade_, grasp_;
  Stream tracker_;  // any tool's poses
  std::deque<BladeSample> blades_;
  std::deque<GraspSample> grasps_;
  std::optional<std::int64_t> next_us_;      // the next step's device time
  std::optional<std::int64_t> offset_us_;    // host - device, smallest seen (clock offset + least delivery delay)
  std::int64_t last_taken_us_ = INT64_MIN;   // the last step's device time
  ModelClockCounters counters_;
};

}  // namespace arnav::host
