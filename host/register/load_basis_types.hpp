#pragma once
// The load basis's data (load_basis.hpp builds and fits it); only Eigen, so the basis
// cache's file reader (basis_cache_file.hpp) builds without the scene and the solver.
#include <Eigen/Core>

#include <string>
#include <vector>

namespace arnav::host {

struct LoadBasisOptions {
  int patches = 48;               // surface patches (3 force modes each), over the whole surface
  bool gravity_modes = true;      // 3 body-force (gravity change) modes (only with a support: on a free body they are rigid)
  int support_clusters = 4;       // parts of the fixed region; each but the first translated (3 modes each); < 2: none
};

struct LoadBasis {
  // Mode j's displacement of vertex v is U.block(3 v, j, 3, 1) (mm). Each mode is scaled
  // to a largest vertex displacement of 1 mm.
  Eigen::MatrixXd U;
  Eigen::MatrixXd G;                    // strain energy metric U^T K U (mN mm per mm^2 of weights)
  std::vector<std::string> mode_kind;   // "patch 3 x", "gravity y", "support 1 z", ...
  std::vector<int> patch_of_vertex;     // patch index per volume vertex (-1: not a surface vertex or fixed)
  int patches = 0, gravity = 0, support = 0;
  bool supported = false;               // false: the scene has no fixed vertices; the basis is taken about a
                                        // weakly held mesh and the rigid part of every mode is removed
  int dofs = 0;
  double stiffness_volume = 0.0;        // sum over tets of E * volume (mN mm): the prior's energy scale
  double build_time_s = 0.0;
  int modes() const { return static_cast<int>(U.cols()); }
};

}  // namespace arnav::host
