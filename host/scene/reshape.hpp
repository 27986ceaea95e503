#pragma once
// Another patient from one we have: the scene's volume scaled about its centroid and warped
// by a smooth random field, everything embedded (organ surface, tumours, vessels) carried by
// the same map. Used where a benchmark must run on livers the models were not developed on
// (the stress matrix of issue 29, arnav-sim-bench --mesh-scale/--mesh-warp-mm). Fixed
// vertices, regions and tets keep their indices; materials, gravity and the model setting are
// the scene's. The embeddings' barycentric weights are kept: exact for the scale, and for the
// warp to second order in its curvature over a tet. The set of tets treated as embedded
// elements (quality below the bound) is kept too; the mesh quality is measured again. Units: mm.
#include <string>

#include "host/scene/scene.hpp"

namespace arnav::host {

struct SceneReshape {
  double scale = 1.0;    // about the volume's vertex centroid; > 0
  double warp_mm = 0.0;  // the warp's largest displacement of a volume vertex (after scaling); >= 0
  unsigned seed = 1;     // the warp's directions, phases and amplitudes
};

// The reshaped scene. Throws std::invalid_argument naming the setting when scale or warp_mm
// are out of range, or when the warp would invert or flatten a tet (use a smaller warp_mm).
Scene reshaped_scene(const Scene& scene, const SceneReshape& reshape);

// "scale 1.3, warp 5 mm (seed 2)" (for notes and benchmark output).
std::string describe(const SceneReshape& reshape);

}  // namespace arnav::host
