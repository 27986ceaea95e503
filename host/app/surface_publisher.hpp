#pragma once
// The host's deforming surfaces on the bus (docs/igtl.md "POLYDATA", docs/overlay.md
// "Surfaces on the bus"): at surfaces.publish_rate_hz a thread of its own takes the model's
// latest snapshot (the one the overlay draws) and the registration, and publishes one
// arnav.surface_mesh_t per surface on ARNAV_SURFACE_<name>: "organ" (the cut volume's
// boundary, cut faces included, as the overlay draws it), "tumour", "tumour2", ... (one per
// tumour of the scene, split along the cut), and "cut" (the cut faces, once there is a
// cut: no "cut" message before the first one). Vertices in Ref (X_RefModel applied), mm;
// only the vertices the triangles use. Nothing is published before a registration exists
// (no Ref coordinates). The model thread never waits for this one: it only takes the
// snapshot pointer the model already shares with the rendering thread.
#include <Eigen/Geometry>

#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "arnav/surface_mesh_t.hpp"
#include "host/app/model_runner.hpp"

namespace arnav::host {

// The messages of one snapshot (sequence 0: the publisher numbers them per channel).
// step_wall_us: the UTC time at which the host ran the snapshot's step.
std::vector<surface_mesh_t> surface_messages(const ModelSnapshot& snap, const Eigen::Isometry3d& X_RefModel, std::int64_t step_wall_us,
                                             std::int64_t publish_wall_us);

struct SurfaceSource {
  std::shared_ptr<const ModelSnapshot> snapshot;   // null: no model (yet)
  std::optional<Eigen::Isometry3d> X_RefModel;     // nullopt: not registered yet
};

struct SurfacePublisherStats {
  std::int64_t rounds = 0;              // publishing rounds run
  std::int64_t rounds_unregistered = 0; // rounds with no registration (or no snapshot): nothing published
  std::int64_t messages = 0;
  std::int64_t model_steps = 0;         // rounds that published a model step not published before
  std::int64_t publish_failures = 0;    // the sink refused a message (LCM publish < 0)
  double build_ms_max = 0.0;            // the most one round took to convert its snapshot
};

class SurfacePublisher {
 public:
  using Source = std::function<SurfaceSource()>;
  // Publishes one message on a channel; false when it failed (counted, not fatal).
  using Sink = std::function<bool(const std::string& channel, const surface_mesh_t& mesh)>;
  // Starts the thread; rate_hz > 0. Live sessions only: the snapshot's session clock is
  // CLOCK_MONOTONIC, mapped to UTC with the host's clocks at publish time.
  // `cpus` (non-empty with model.cpu_partition active): the thread runs only there, off the
  // model's core. `model_started_mono_us`: CLOCK_MONOTONIC when the model thread started
  // (before its first step): the rest state's time stamp (-1: this constructor's time).
  SurfacePublisher(double rate_hz, Source source, Sink sink, std::vector<int> cpus = {}, std::int64_t model_started_mono_us = -1);
  ~SurfacePublisher();
  SurfacePublisher(const SurfacePublisher&) = delete;
  SurfacePublisher& operator=(const SurfacePublisher&) = delete;
  void stop();
  SurfacePublisherStats stats() const;
  // Why the thread could not be pinned to `cpus` (empty: it was, or none were given).
  std::string pin_error() const;

 private:
  void loop();
  void publish_round();

  double rate_hz_;
  Source source_;
  Sink sink_;
  std::vector<int> cpus_;
  std::string pin_error_;                          // mutex_
  std::map<std::string, std::int64_t> sequence_;   // per channel (publisher thread)
  std::int64_t model_started_mono_us_;
  std::int64_t last_step_ = -1, last_step_wall_us_ = 0;  // publisher thread
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  bool stopping_ = false;
  SurfacePublisherStats stats_;
  std::thread thread_;
};

}  // namespace arnav::host
