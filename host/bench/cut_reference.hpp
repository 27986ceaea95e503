#pragma once
// arnav-bench cut --reference MESH: each run's cut against the same scalpel path cut on a
// reference mesh (the paper-size bundled liver, 26,054 tets) with the same model kind
// (docs/benchmarks.md, "Cutting: error against a reference mesh"). At the last frame of the
// run: tumour-centroid error (volume centroid of the tumour surface split along the cut) and
// cut-surface error (symmetric distance between the two runs' cut faces, current
// configuration), next to the run's frame time: error against run time, CSV and a plot.
// Frame World, units mm, ms.
#include <Eigen/Core>

#include <map>
#include <string>
#include <tuple>
#include <vector>

#include "host/bench/cut_bench.hpp"
#include "host/cut/blade.hpp"
#include "host/cut/cut_session.hpp"
#include "host/sim/model_factory.hpp"

namespace arnav::host {

// What a cut run ends with.
struct CutOutcome {
  bool has_tumour = false;
  Eigen::Vector3d tumour_centroid_World_mm = Eigen::Vector3d::Zero();
  std::vector<cut::Triangle> cut_faces;  // boundary faces whose three vertices lie on a cut (both lips), current positions
  bool healthy = true;
  int frames = 0, tets = 0;
  double wall_s = 0.0;
  std::string warning;
};

CutOutcome cut_outcome(cut::CutSession& session);

// Symmetric distance between two triangle sets: every triangle's centroid and corners to the
// nearest point of the other set; area-weighted mean over both directions and the largest.
struct SurfaceDistance {
  double mean_mm = 0.0, max_mm = 0.0;
  bool valid = false;  // both sets non-empty
};
SurfaceDistance surface_distance(const std::vector<cut::Triangle>& a, const std::vector<cut::Triangle>& b);

// Reference runs, one per (scenario, model label, frames), made when first asked for.
class CutReferences {
 public:
  explicit CutReferences(const CutBenchOptions& options) : options_(options) {}
  const CutOutcome& get(const std::string& scenario, const ModelVariant& variant, int frames, const cut::CutSessionSettings& settings);
  const std::string& mesh() const { return options_.reference_mesh; }

 private:
  const CutBenchOptions& options_;
  std::map<std::tuple<std::string, std::string, int>, CutOutcome> done_;
};

// Fills the row's reference columns: the run (session at its last frame) against the reference.
void add_reference_errors(CutReferences& references, const std::string& scenario, const ModelVariant& variant,
                          const cut::CutSessionSettings& settings, cut::CutSession& session, CutBenchRow& row);

// cut_reference.csv (one row per run with reference columns) and cut_reference.png (tumour-
// centroid and cut-surface error against median frame time, per scenario).
void write_cut_reference_csv(const std::string& path, const std::vector<CutBenchRow>& rows);
void write_cut_reference_png(const std::string& path, const std::vector<CutBenchRow>& rows);

}  // namespace arnav::host
