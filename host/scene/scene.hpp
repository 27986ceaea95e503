#pragma once
// Patient scene: a YAML file declaring the organ, its volume mesh, internal structures,
// regions and materials, boundary conditions, gravity, time step and the tissue model.
// Loading builds only what the file declares (no vessels -> SimProblem::vessels empty).
// Units: mm, kg, s; Young's modulus kPa; density kg/mm^3; gravity mm/s^2. The schema is
// documented in docs/scene.md; unknown keys are errors naming the file and line.
#include <optional>
#include <string>
#include <vector>

#include "host/scene/embedding.hpp"
#include "host/mesh/mesh_quality.hpp"
#include "host/scene/scene_spec.hpp"
#include "host/mesh/tet_mesh.hpp"
#include "host/sim/model_config.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host {

// A closed surface inside the organ (tumour), carried by the volume.
struct EmbeddedSurface {
  std::string name;
  TriMesh rest;            // rest shape, World
  Embedding embedding;     // in Scene::problem.mesh
  Eigen::Vector3d rest_centroid_World_mm = Eigen::Vector3d::Zero();  // volume centroid
};

// Vessel centerlines, carried by the volume for display (and, when the scene asks for
// beams, also given to the tissue model through SimProblem::vessels).
struct EmbeddedVessels {
  VesselTree rest;
  Embedding embedding;
};

struct Scene {
  std::string source;                     // scene file path
  SimProblem problem;                     // mesh, materials, fixed vertices, gravity, vessels
  ModelConfig model;
  int model_line = 0;                     // first line of the 'model:' section in the scene file
  double time_step_s = 1.0 / 60.0;
  int frames = 60;                        // default run length for arnav-sim
  TriMesh organ_surface;                  // display surface (as loaded; may be finer than the volume)
  Embedding organ_embedding;              // organ_surface in problem.mesh
  std::vector<EmbeddedSurface> tumours;
  std::optional<EmbeddedVessels> vessels;
  std::vector<std::string> notes;         // what loading did (flips, meshing, counts, mesh quality)
  TetMeshQuality mesh_quality;            // of the rest volume (also in notes)
  std::optional<CuttingSpec> cutting;     // the scalpel cuts the organ (docs/cut.md); only when declared
};

// Reads and builds a scene. Throws LoadError naming the file (scene or mesh), the line
// and the fix.
Scene load_scene(const std::string& path);

// Parses and checks the scene text without reading referenced files (for fuzzing and
// schema tests). Throws LoadError like load_scene.
void check_scene_text(const std::string& yaml_text, const std::string& source);

// Positions of the embedded structures for the current volume positions.
Eigen::Vector3d tumour_centroid_World_mm(const Scene& scene, int tumour, const Eigen::Matrix3Xd& x_World_mm);

// Organ-surface vertices within radius_mm of the lowest one (smallest z in World: the tip
// of a hanging lobe): where the benchmarks' tool grasps the organ.
std::vector<int> lowest_surface_patch(const Scene& scene, double radius_mm);

}  // namespace arnav::host
