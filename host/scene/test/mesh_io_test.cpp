// Mesh loaders on real SOFA liver files and tiny hand-written files, and every validation
// error the loaders report (with file, line and fix).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>

#include "host/scene/box_mesh.hpp"
#include "host/scene/load_error.hpp"
#include "host/scene/mesh_formats.hpp"
#include "host/scene/mesh_io.hpp"
#include "host/scene/test/test_paths.hpp"
#include "host/scene/vtk_legacy.hpp"

namespace arnav::host {
namespace {

using test::scratch;
using test::data_meshes;
using test::write_file;

// A unit tetrahedron's surface, outward, plus a trailing unused vertex.
const char* kTetObj =
    "# tiny\n"
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 5 5 5\n"
    "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const LoadError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(SurfaceLoaders, TinyObjLoadsDropsUnusedVertex) {
  const std::string path = write_file(scratch("obj"), "tet.obj", kTetObj);
  SurfaceCheck check;
  const TriMesh s = load_surface(path, &check);
  EXPECT_EQ(s.positions_World_mm.cols(), 4);
  EXPECT_EQ(s.tris.size(), 4u);
  EXPECT_EQ(check.removed_unused_vertices, 1);
  EXPECT_FALSE(check.flipped);
  EXPECT_NEAR(check.volume_mm3, 1.0 / 6.0, 1e-12);
}

TEST(SurfaceLoaders, InwardSurfaceIsFlipped) {
  const std::string path = write_file(scratch("obj"), "inward.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 4 2\nf 1 3 4\nf 2 4 3\n");
  SurfaceCheck check;
  load_surface(path, &check);
  EXPECT_TRUE(check.flipped);
  EXPECT_NEAR(check.volume_mm3, 1.0 / 6.0, 1e-12);
}

TEST(SurfaceLoaders, ObjPolygonsSlashesAndNegativeIndices) {
  const TriMesh s = parse_obj("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1/1/1 2/2/2 3//3 4\nf -4 -2 -1\n", "quad.obj");
  ASSERT_EQ(s.tris.size(), 3u);
  EXPECT_EQ(s.tris[0], (std::array<int, 3>{0, 1, 2}));
  EXPECT_EQ(s.tris[1], (std::array<int, 3>{0, 2, 3}));
  EXPECT_EQ(s.tris[2], (std::array<int, 3>{0, 2, 3}));
}

TEST(SurfaceLoaders, OffAndAsciiVtkPolydata) {
  const std::string dir = scratch("off");
  const TriMesh off = load_surface(write_file(dir, "tet.off", "OFF\n# c\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"));
  EXPECT_EQ(off.tris.size(), 4u);
  const TriMesh vtk = load_surface(write_file(dir, "tet.vtk",
                                              "# vtk DataFile Version 3.0\ntiny\nASCII\nDATASET POLYDATA\nPOINTS 4 float\n0 0 0 1 0 0 0 1 0 0 0 1\n"
                                              "POLYGONS 4 16\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\nPOINT_DATA 4\nSCALARS s float 1\n"));
  EXPECT_EQ(vtk.tris.size(), 4u);
}

TEST(SurfaceLoaders, BinaryVtkPolydataRoundTrip) {
  // Big-endian binary as VTK writes it.
  std::string data = "# vtk DataFile Version 3.0\nbin\nBINARY\nDATASET POLYDATA\nPOINTS 4 float\n";
  auto put32 = [&](std::uint32_t v) {
    for (int s = 24; s >= 0; s -= 8) data.push_back(static_cast<char>((v >> s) & 0xff));
  };
  const float p[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  for (float f : p) {
    std::uint32_t bits;
    std::memcpy(&bits, &f, 4);
    put32(bits);
  }
  data += "\nPOLYGONS 4 16\n";
  const int c[16] = {3, 0, 2, 1, 3, 0, 1, 3, 3, 0, 3, 2, 3, 1, 2, 3};
  for (int v : c) put32(static_cast<std::uint32_t>(v));
  data += "\n";
  const TriMesh s = load_surface(write_file(scratch("bin"), "tet.vtk", data));
  EXPECT_EQ(s.tris.size(), 4u);
  EXPECT_DOUBLE_EQ(s.positions_World_mm(2, 3), 1.0);
}

TEST(SurfaceLoaders, RealSofaLiverSurfaces) {
  SurfaceCheck check;
  const TriMesh vtk = load_surface(data_meshes() + "liver.vtk", &check);
  EXPECT_EQ(vtk.positions_World_mm.cols(), 5008);
  EXPECT_EQ(vtk.tris.size(), 10000u);
  EXPECT_TRUE(check.flipped);                      // stored with inward normals
  EXPECT_NEAR(check.volume_mm3, 1.477e6, 0.01e6);  // ~1.5 l: a real adult liver in mm
  EXPECT_EQ(check.components, 4);                  // the liver and 3 tiny bubbles (4 vertices each)
  TriMesh largest = vtk;
  EXPECT_EQ(keep_largest_component(largest), 12);
  EXPECT_EQ(largest.positions_World_mm.cols(), 4996);
  const TriMesh smooth = load_surface(data_meshes() + "liver-smooth.obj");
  EXPECT_EQ(smooth.positions_World_mm.cols(), 2194);
  const TriMesh coarse = load_surface(data_meshes() + "liver.obj", &check);
  EXPECT_EQ(check.removed_unused_vertices, 42);    // 181 vertices, 139 used by faces
  EXPECT_EQ(load_surface(data_meshes() + "liver2.obj").positions_World_mm.cols(), 1170);
}

TEST(SurfaceLoaders, BrokenSofaVtkIsRejectedWithLocationAndFix) {
  const std::string path = data_meshes() + "liver_for_test_broken.vtk";
  const std::string e = error_of([&] { load_surface(path); });
  SCOPED_TRACE(e);
  EXPECT_NE(e.find("liver_for_test_broken.vtk"), std::string::npos);
  EXPECT_NE(e.find("byte offset"), std::string::npos);
  EXPECT_NE(e.find("POINTS 508"), std::string::npos);
  EXPECT_NE(e.find("Fix:"), std::string::npos);
}

TEST(SurfaceValidation, EachErrorNamesLineAndFix) {
  const std::string dir = scratch("bad");
  struct Case {
    const char* name;
    std::string text;
    const char* expect;
  };
  const std::vector<Case> cases = {
      {"open.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\n", "open surface"},
      {"nonmanifold.obj", std::string(kTetObj) + "f 1 2 5\n", "non-manifold"},
      {"orient.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 4 3\n", "inconsistent orientation"},
      {"nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\n", "nan.obj:2"},
      {"range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "refers to vertex 8"},
      {"degenerate.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 2 3 4\nf 1 3 4\n", "degenerate"},
      {"repeat.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 1 2\n", "uses vertex 0 twice"},
      {"badface.obj", "v 0 0 0\nf 1 x 2\n", "bad face vertex reference"},
  };
  for (const auto& c : cases) {
    const std::string e = error_of([&] { load_surface(write_file(dir, c.name, c.text)); });
    SCOPED_TRACE(e);
    EXPECT_NE(e.find(c.name), std::string::npos);
    EXPECT_NE(e.find(c.expect), std::string::npos);
    EXPECT_NE(e.find("Fix:"), std::string::npos);
  }
  // Line numbers: the open edge belongs to the face on line 5 or later.
  const std::string e = error_of([&] { load_surface(dir + "/open.obj"); });
  EXPECT_TRUE(e.find("open.obj:5:") != std::string::npos || e.find("open.obj:6:") != std::string::npos ||
              e.find("open.obj:7:") != std::string::npos)
      << e;
}

TEST(VolumeLoaders, RealGmshV1Livers) {
  TetMeshCheck check;
  const TetMesh a = load_volume(data_meshes() + "liver.msh", &check);
  EXPECT_EQ(a.num_vertices(), 181);
  EXPECT_EQ(a.num_tets(), 596);
  EXPECT_GT(check.min_quality, 0.0);
  const TetMesh b = load_volume(data_meshes() + "liver2.msh", &check);
  EXPECT_EQ(b.num_vertices(), 507);  // node numbers are not contiguous in this file
  EXPECT_EQ(b.num_tets(), 1493);
  EXPECT_FALSE(b.surface_tris.empty());
}

TEST(VolumeLoaders, GmshV2WithPhysicalRegions) {
  const std::string text =
      "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$PhysicalNames\n2\n3 7 \"liver\"\n3 9 \"tumour\"\n$EndPhysicalNames\n"
      "$Nodes\n5\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 1 1\n$EndNodes\n"
      "$Elements\n3\n1 2 2 7 1 1 2 3\n2 4 2 7 1 1 2 3 4\n3 4 2 9 2 2 3 4 5\n$EndElements\n";
  // Node 5 = (1,1,1) lies on the positive side of face (2,3,4): both tets are positive.
  const TetMesh m = load_volume(write_file(scratch("gmsh"), "two.msh", text));
  ASSERT_EQ(m.num_tets(), 2);  // the triangle (type 2) is skipped
  EXPECT_EQ(m.region_names, (std::vector<std::string>{"liver", "tumour"}));
  EXPECT_EQ(m.tet_region, (std::vector<int>{0, 1}));
  EXPECT_EQ(m.surface_tris.size(), 6u);
}

TEST(VolumeLoaders, GmshErrors) {
  const std::string dir = scratch("gmsh_bad");
  auto err = [&](const char* name, const std::string& text) { return error_of([&] { load_volume(write_file(dir, name, text)); }); };
  EXPECT_NE(err("v4.msh", "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n").find("msh2"), std::string::npos);
  EXPECT_NE(err("bin.msh", "$MeshFormat\n2.2 1 8\n$EndMeshFormat\n").find("binary"), std::string::npos);
  const std::string nodes = "$NOD\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$ENDNOD\n";
  const std::string inverted = err("inv.msh", nodes + "$ELM\n1\n1 4 1 1 4 1 3 2 4\n$ENDELM\n");
  EXPECT_NE(inverted.find("inv.msh:10:"), std::string::npos) << inverted;
  EXPECT_NE(inverted.find("inverted"), std::string::npos) << inverted;
  const std::string missing = err("missing.msh", nodes + "$ELM\n1\n1 4 1 1 4 1 2 3 99\n$ENDELM\n");
  EXPECT_NE(missing.find("missing.msh:10:"), std::string::npos) << missing;
  EXPECT_NE(missing.find("node 99"), std::string::npos) << missing;
  const std::string flat = err("flat.msh", "$NOD\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 1 1 0\n$ENDNOD\n$ELM\n1\n1 4 1 1 4 1 2 3 4\n$ENDELM\n");
  EXPECT_NE(flat.find("degenerate"), std::string::npos) << flat;
  const std::string nan = err("nan.msh", "$NOD\n1\n1 0 nan 0\n$ENDNOD\n$ELM\n0\n$ENDELM\n");
  EXPECT_NE(nan.find("nan.msh:3:"), std::string::npos) << nan;
  const std::string count = err("count.msh", "$NOD\n3\n1 0 0 0\n2 1 0 0\n$ENDNOD\n$ELM\n0\n$ENDELM\n");
  EXPECT_NE(count.find("count.msh"), std::string::npos) << count;
  EXPECT_NE(err("hex.msh", nodes + "$ELM\n1\n1 5 1 1 8 1 2 3 4 1 2 3 4\n$ENDELM\n").find("not a linear tetrahedron"), std::string::npos);
}

TEST(VolumeLoaders, TetGenFilesOneBasedWithRegions) {
  const std::string dir = scratch("tetgen");
  write_file(dir, "m.node", "# nodes\n5 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 1 1\n");
  write_file(dir, "m.ele", "2 4 1\n1 1 2 3 4 1\n2 2 3 4 5 2\n");
  const TetMesh m = load_volume(dir + "/m.ele");
  EXPECT_EQ(m.num_vertices(), 5);
  EXPECT_EQ(m.tets[0], (std::array<int, 4>{0, 1, 2, 3}));
  EXPECT_EQ(m.region_names, (std::vector<std::string>{"region_1", "region_2"}));
  EXPECT_EQ(m.tet_region, (std::vector<int>{0, 1}));
  // Region attributes are reals (TetGen -A): fractional and huge values are regions too
  // (a huge one once overflowed an integer conversion; found by fuzz_scene_mesh_parsers).
  write_file(dir, "r.node", "5 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 1 1\n");
  write_file(dir, "r.ele", "2 4 1\n1 1 2 3 4 0.5\n2 2 3 4 5 5888888888888888888888888888888888888888888888888888888\n");
  const TetMesh r = load_volume(dir + "/r.ele");
  EXPECT_EQ(r.region_names, (std::vector<std::string>{"region_0.5", "region_5.88888888888889e+54"}));
  write_file(dir, "bad.node", "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n");
  write_file(dir, "bad.ele", "1 4 0\n0 0 1 2 7\n");
  const std::string e = error_of([&] { load_volume(dir + "/bad.node"); });
  EXPECT_NE(e.find("bad.ele:2:"), std::string::npos) << e;
  EXPECT_NE(e.find("node 7"), std::string::npos) << e;
  write_file(dir, "inv.node", "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n");
  write_file(dir, "inv.ele", "1 4 0\n0 0 2 1 3\n");
  const std::string inv = error_of([&] { load_volume(dir + "/inv.ele"); });
  EXPECT_NE(inv.find("inv.ele:2:"), std::string::npos) << inv;
  EXPECT_NE(inv.find("tetrahedron 0"), std::string::npos) << inv;
}

TEST(VolumeLoaders, VtkUnstructuredRoundTrip) {
  const TetMesh box = make_box_tet_mesh(2, 3, 2, Eigen::Vector3d(10, 20, 30));
  const std::string path = scratch("vtku") + "/box.vtk";
  write_vtk_volume(path, box, box.rest_positions_World_mm);
  const TetMesh back = load_volume(path);
  EXPECT_EQ(back.num_vertices(), box.num_vertices());
  EXPECT_EQ(back.tets, box.tets);
  EXPECT_TRUE(back.rest_positions_World_mm.isApprox(box.rest_positions_World_mm));
  // A surface given as a volume (and the reverse) is refused clearly.
  EXPECT_NE(error_of([&] { load_volume(data_meshes() + "liver.vtk"); }).find("POLYDATA"), std::string::npos);
  EXPECT_NE(error_of([&] { load_surface(path); }).find("UNSTRUCTURED_GRID"), std::string::npos);
}

TEST(VtkLegacy, HeaderErrors) {
  auto err = [](const std::string& text) { return error_of([&] { parse_vtk_legacy(text, "h.vtk"); }); };
  EXPECT_NE(err("hello\n").find("not a legacy VTK"), std::string::npos);
  EXPECT_NE(err("# vtk DataFile Version 5.1\nt\nASCII\nDATASET POLYDATA\n").find("4.2"), std::string::npos);
  EXPECT_NE(err("# vtk DataFile Version 3.0\nt\nASCII\nDATASET STRUCTURED_POINTS\n").find("not supported"), std::string::npos);
  EXPECT_NE(err("# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS 2 float\n0 0 0 1 1 1\nBOGUS 3\n").find("h.vtk:7:"),
            std::string::npos);
  EXPECT_NE(err("# vtk DataFile Version 3.0\nt\nBINARY\nDATASET POLYDATA\nPOINTS 100 float\n\x01\x02").find("ends before"),
            std::string::npos);
}

}  // namespace
}  // namespace arnav::host
