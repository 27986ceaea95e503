#pragma once
// arnav-bench transection: a full transection of a patient's liver by the blade
// (host/cut/transection.hpp) with every model variant, free (no gravity, nothing fixed) and
// held (the scene's fixed vertices and gravity), at the scene's own resolution. One JSON
// object per run on stdout (issue 23, docs/benchmarks.md).
#include <string>
#include <vector>

namespace arnav::host {

struct TransectionBenchOptions {
  std::vector<std::string> scenes;           // scene files (default: the three patients' full-resolution scenes)
  std::vector<std::string> setting_prefixes;  // run only the variants whose label starts with one of these
  std::vector<std::string> supports{"free", "held"};
  int threads = 1;
  double margin_mm = 30.0;  // the blade's reach beyond the organ (TransectionSettings::margin_mm)
};

// Returns the number of runs with an unhealthy step, a broken mesh or a side volume off by
// more than 1e-4 (free) / 5e-2 (held) of the expected one. Throws LoadError for a bad scene.
int run_transection_bench(const TransectionBenchOptions& options);

}  // namespace arnav::host
