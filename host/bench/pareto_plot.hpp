#pragma once
// PNG plot of arnav-bench deform results: per scenario, tumour-centroid error against
// median frame time (both log scale), one colour per model kind, the Pareto front joined,
// and the 500 Hz / 60 Hz budgets and the 1 mm target marked. Drawn with OpenCV.
#include <string>

#include "host/bench/deform_bench.hpp"

namespace arnav::host {

// Axis and legend texts; empty: the deform benchmark's.
struct ParetoLabels {
  std::string x, y, note;
};

void write_pareto_png(const std::string& path, const DeformBenchResult& result, const ParetoLabels& labels = {});

}  // namespace arnav::host
