#pragma once
// The tissue model of a navigation session, stepped at its own rate: on its own thread
// (live sessions) or by the caller (replay, deterministic). After every step it publishes
// an immutable snapshot of what the overlay draws (organ surface, tumours and their margin
// shells, vessel centerlines), all in Model (the scene frame, mm).
//
// Seam for the cutting and contact stages (host/cut, not part of this build): the scalpel
// in Model is handed in with set_scalpel(); a cutting stage would turn it into
// attachments/cuts before each step and fill ModelSnapshot::cut_surface.
#include <Eigen/Core>

#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include "host/scene/scene.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host {

struct ModelSnapshot {
  std::int64_t step = 0;
  std::int64_t step_done_mono_us = 0;   // session clock when the step finished
  double step_ms = 0.0;                 // wall time of the step
  bool healthy = true;
  std::string warning;
  TriMesh organ;
  std::vector<TriMesh> tumours;
  std::vector<TriMesh> margins;
  std::vector<Eigen::Vector3d> tumour_centroids_mm;
  std::optional<VesselTree> vessels;
  std::optional<TriMesh> cut_surface;   // filled by the cutting stage (host/cut) when it exists
  Eigen::Matrix3Xd volume_positions_mm; // the tet mesh's vertices (carries the cut trace)
};

class ModelRunner {
 public:
  // Builds the scene's tissue model (gravity per `gravity`). `nice` > 0 lowers the model
  // thread's scheduling priority (Linux nice, per thread). Throws std::invalid_argument.
  ModelRunner(const Scene& scene, double rate_hz, bool gravity, double margin_mm, int nice = 0);
  ~ModelRunner();
  ModelRunner(const ModelRunner&) = delete;
  ModelRunner& operator=(const ModelRunner&) = delete;

  // Live: steps on a thread every 1/rate_hz until stop().
  void start();
  void stop();
  // Replay: performs the steps due up to now_us (session clock), at most max_steps.
  int advance_to(std::int64_t now_us, int max_steps = 10);

  void set_scalpel(const std::optional<std::array<Eigen::Vector3d, 2>>& blade_Model_mm);
  std::shared_ptr<const ModelSnapshot> snapshot() const;
  std::int64_t steps() const { return steps_.load(); }
  // Wall times of every step (ms), for the summary.
  std::vector<double> step_times_ms() const;

 private:
  void step_once(std::int64_t now_us);
  const Scene& scene_;
  double rate_hz_;
  double margin_mm_;
  int nice_ = 0;
  std::unique_ptr<TissueModel> model_;
  mutable std::mutex mutex_;
  std::shared_ptr<const ModelSnapshot> snapshot_;
  std::optional<std::array<Eigen::Vector3d, 2>> scalpel_;
  std::vector<double> step_ms_;
  std::atomic<std::int64_t> steps_{0};
  std::int64_t next_step_us_ = -1;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::condition_variable cv_;
};

}  // namespace arnav::host
