// libFuzzer target: blade sweeps read from the input bytes cut a small box mesh (several
// strokes, sweeps snapped to the grid now and then); every invariant of the cut is checked
// after each stroke and a violation aborts (positive tets, conserved volume, closed,
// 2-manifold, consistently oriented boundary). In the sanitizer build this is the smoke run
// of random blade sweeps over the index maps and per-element data the cut rewrites.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>

#include "host/cut/mesh_checks.hpp"
#include "host/cut/tet_cutter.hpp"
#include "host/mesh/box_mesh.hpp"

using namespace arnav::host;
using namespace arnav::host::cut;

namespace {
struct Bytes {
  const std::uint8_t* p;
  std::size_t n;
  bool empty() const { return n == 0; }
  int byte() {
    if (n == 0) return 0;
    --n;
    return *p++;
  }
  double coord() { return -10.0 + 60.0 * byte() / 255.0; }  // mm, around the 40 x 30 x 20 box
};
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Bytes in{data, size};
  const int cells = 2 + in.byte() % 3;
  const double snap = 0.02 + 0.45 * (in.byte() / 255.0);
  TetMesh mesh = make_box_tet_mesh(cells + 1, cells, cells, Eigen::Vector3d(40, 30, 20));
  const double volume = check_cut_mesh(mesh).total_volume_mm3;
  CutSettings settings;
  settings.snap_fraction = snap;
  settings.move_snapped_vertices = in.byte() % 2 == 0;
  TetCutter cutter(mesh, settings);
  Eigen::Matrix3Xd x = mesh.rest_positions_World_mm, v = Eigen::Matrix3Xd::Zero(3, x.cols());
  for (int stroke = 0; stroke < 4 && !in.empty(); ++stroke) {
    if (stroke > 0) cutter.begin_stroke();
    BladeSegment prev{Eigen::Vector3d(in.coord(), in.coord(), in.coord()), Eigen::Vector3d(in.coord(), in.coord(), in.coord())};
    const int frames = 1 + in.byte() % 8;
    const bool grid = in.byte() % 4 == 0;
    for (int f = 0; f < frames && !in.empty(); ++f) {
      BladeSegment cur{Eigen::Vector3d(in.coord(), in.coord(), in.coord()), Eigen::Vector3d(in.coord(), in.coord(), in.coord())};
      if (grid)
        for (int k = 0; k < 3; ++k) {
          cur.tip_World_mm[k] = std::round(cur.tip_World_mm[k] / 10) * 10;
          cur.heel_World_mm[k] = std::round(cur.heel_World_mm[k] / 10) * 10;
        }
      cutter.step({prev, cur, 1 + f % 3, {}}, x, v);
      prev = cur;
    }
    cutter.finish_stroke(x, v);
    const CutMeshCheck c = check_cut_mesh(cutter.mesh());
    if (!c.valid() || std::abs(c.total_volume_mm3 / volume - 1.0) > 1e-9 || x.cols() != cutter.mesh().num_vertices() ||
        v.cols() != cutter.mesh().num_vertices())
      std::abort();
  }
  return 0;
}
