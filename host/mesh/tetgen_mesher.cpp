#include "host/mesh/tetgen_mesher.hpp"

#include <tetgen.h>

#include <Eigen/LU>

#include <chrono>
#include <cstdio>
#include <sstream>
#include <vector>

#include "host/mesh/load_error.hpp"
#include "host/mesh/mesh_validation.hpp"

namespace arnav::host {
namespace {

std::string tetgen_failure(int code) {
  switch (code) {
    case 1: return "TetGen ran out of memory";
    case 3: return "TetGen found a self-intersection in the surface";
    case 4: return "TetGen found a very small input feature (nearly touching parts of the surface)";
    case 5: return "TetGen found two input facets that are very close or overlap";
    case 10: return "TetGen rejected the input";
    default: return "TetGen failed with an internal error (code " + std::to_string(code) + ")";
  }
}

}  // namespace

TetMesh tetrahedralize_surface(const TriMesh& surface, const TetGenSettings& s, const std::string& source,
                               TetGenReport* report) {
  if (s.max_radius_edge_ratio < 1.1 && s.max_radius_edge_ratio != 0.0)
    throw_load_error(source, 0, "quality bound (radius-edge ratio) " + std::to_string(s.max_radius_edge_ratio) + " is below 1.1",
                     "use 1.1 or more (TetGen may not terminate below that); 2.0 is a good default");
  std::ostringstream sw;
  sw << "pQ";
  if (s.keep_surface) sw << "Y";
  if (s.max_radius_edge_ratio > 0) {
    sw << "q" << s.max_radius_edge_ratio;
    if (s.min_dihedral_deg > 0) sw << "/" << s.min_dihedral_deg;
  }
  if (s.max_volume_mm3 > 0) sw << "a" << s.max_volume_mm3;
  if (s.optimisation_level > 10)
    throw_load_error(source, 0, "TetGen optimisation level " + std::to_string(s.optimisation_level) + " is above 10", "use 0..10");
  if (s.optimisation_level >= 0) sw << "O" << s.optimisation_level << "/7";
  std::string switches = sw.str();

  tetgenio in, out;
  in.firstnumber = 0;
  in.numberofpoints = static_cast<int>(surface.positions_World_mm.cols());
  in.pointlist = new REAL[3 * in.numberofpoints];
  for (int i = 0; i < in.numberofpoints; ++i)
    for (int k = 0; k < 3; ++k) in.pointlist[3 * i + k] = surface.positions_World_mm(k, i);
  in.numberoffacets = static_cast<int>(surface.tris.size());
  in.facetlist = new tetgenio::facet[in.numberoffacets];
  for (int f = 0; f < in.numberoffacets; ++f) {
    tetgenio::facet& facet = in.facetlist[f];
    tetgenio::init(&facet);
    facet.numberofpolygons = 1;
    facet.polygonlist = new tetgenio::polygon[1];
    tetgenio::init(&facet.polygonlist[0]);
    facet.polygonlist[0].numberofvertices = 3;
    facet.polygonlist[0].vertexlist = new int[3];
    for (int k = 0; k < 3; ++k) facet.polygonlist[0].vertexlist[k] = surface.tris[f][k];
  }
  const auto t0 = std::chrono::steady_clock::now();
  // Self-intersections first, with TetGen's detection mode (-d): libtet 1.5.0 crashes in
  // its clean-up when meshing fails on an intersecting surface instead of reporting it.
  {
    tetgenio found;
    std::string detect = "pdQ";
    try {
      tetrahedralize(detect.data(), &in, &found);
    } catch (int code) {
      throw_load_error(source, 0, tetgen_failure(code) + " while checking the surface for self-intersections",
                       "repair the surface");
    }
    if (found.numberoftrifaces > 0) {
      std::ostringstream where;
      where << "the surface intersects itself (" << found.numberoftrifaces << " triangles involved; one has vertices";
      for (int k = 0; k < 3; ++k) where << " " << found.trifacelist[k] - found.firstnumber;
      const int v = found.trifacelist[0] - found.firstnumber;
      if (v >= 0 && v < found.numberofpoints)
        where << " near (" << found.pointlist[3 * v] << ", " << found.pointlist[3 * v + 1] << ", " << found.pointlist[3 * v + 2] << ") mm";
      where << ")";
      throw_load_error(source, 0, "TetGen found a self-intersection: " + where.str(),
                       "repair the surface (remove self-intersections, e.g. MeshLab 'Select self intersecting faces' and "
                       "remesh); TetGen cannot mesh an intersecting surface");
    }
  }
  try {
    tetrahedralize(switches.data(), &in, &out);
  } catch (int code) {
    throw_load_error(source, 0, tetgen_failure(code) + " while meshing with switches -" + switches,
                     code == 3 || code == 4 || code == 5
                         ? "repair the surface (remove self-intersections, e.g. with MeshLab 'Select self intersecting faces')"
                         : "check the surface and the quality/size settings");
  }
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  if (out.numberoftetrahedra <= 0 || out.numberofcorners != 4)
    throw_load_error(source, 0, "TetGen produced no linear tetrahedra (switches -" + switches + ")", "check the surface is closed");
  TetMesh mesh;
  mesh.rest_positions_World_mm.resize(3, out.numberofpoints);
  for (int i = 0; i < out.numberofpoints; ++i)
    for (int k = 0; k < 3; ++k) mesh.rest_positions_World_mm(k, i) = out.pointlist[3 * i + k];
  mesh.tets.resize(out.numberoftetrahedra);
  for (int t = 0; t < out.numberoftetrahedra; ++t) {
    // TetGen orders a tet's corners with negative orientation in our convention (its
    // fourth corner lies below the first three); swap two to make it positive.
    auto& tet = mesh.tets[t];
    for (int k = 0; k < 4; ++k) tet[k] = out.tetrahedronlist[4 * t + k] - out.firstnumber;
    Eigen::Matrix3d D;
    for (int k = 0; k < 3; ++k) D.col(k) = mesh.rest_positions_World_mm.col(tet[k + 1]) - mesh.rest_positions_World_mm.col(tet[0]);
    if (D.determinant() < 0) std::swap(tet[2], tet[3]);
  }
  validate_tet_mesh(mesh, source + " (TetGen output)");
  if (report) {
    report->switches = "-" + switches;
    report->input_vertices = in.numberofpoints;
    report->input_triangles = in.numberoffacets;
    report->wall_time_ms = ms;
  }
  return mesh;
}

}  // namespace arnav::host
