// Mesh loaders on real SOFA liver files and tiny hand-written files, and every validation
// error the loaders report (with file, line and fix).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "host/mesh/box_mesh.hpp"
#include "host/mesh/load_error.hpp"
#include "host/mesh/mesh_formats.hpp"
#include "host/mesh/mesh_io.hpp"
#include "host/mesh/test/test_paths.hpp"
#include "host/mesh/vtk_legacy.hpp"
#include "protocol/testing/error_of.hpp"

namespace arnav::host {
namespace {

using arnav::testing::error_of;

using test::scratch;
using test::data_meshes;
using test::write_file;

// A unit tetrahedron's surface, outward, plus a trailing unused vertex.
const char* kTetObj =
    "# tiny\n"
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 5 5 5\n"
    "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

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

// PLY: a tet surface written as ASCII, binary little- and big-endian, with extra vertex
// and face properties (normals, colours, a texture-coordinate list) that must be skipped.
std::string ply_tet(const std::string& format) {
  std::string h = "ply\nformat " + format + " 1.0\ncomment unit tet, mm\nelement vertex 4\nproperty float x\nproperty float y\n"
                  "property double z\nproperty uchar red\nelement face 4\nproperty list uchar int vertex_indices\n"
                  "property list uchar float texcoord\nelement edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n";
  const double p[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const int f[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  if (format == "ascii") {
    for (auto& v : p) h += std::to_string(v[0]) + " " + std::to_string(v[1]) + " " + std::to_string(v[2]) + " 200\n";
    for (auto& t : f) h += "3 " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " + std::to_string(t[2]) + " 2 0.5 0.5\n";
    return h + "0 1\n";
  }
  const bool big = format == "binary_big_endian";
  auto put = [&](const void* data, int n) {
    const char* c = static_cast<const char*>(data);
    for (int k = 0; k < n; ++k) h += big ? c[n - 1 - k] : c[k];
  };
  for (auto& v : p) {
    const float x = static_cast<float>(v[0]), y = static_cast<float>(v[1]);
    put(&x, 4);
    put(&y, 4);
    put(&v[2], 8);
    h += static_cast<char>(200);
  }
  for (auto& t : f) {
    h += static_cast<char>(3);
    for (int k = 0; k < 3; ++k) put(&t[k], 4);
    h += static_cast<char>(2);
    const float uv = 0.5f;
    put(&uv, 4);
    put(&uv, 4);
  }
  const int e[2] = {0, 1};
  put(&e[0], 4);
  put(&e[1], 4);
  return h;
}

TEST(SurfaceLoaders, PlyAsciiAndBinaryBothEndians) {
  const std::string dir = scratch("ply");
  for (const std::string format : {"ascii", "binary_little_endian", "binary_big_endian"}) {
    SCOPED_TRACE(format);
    SurfaceCheck check;
    const TriMesh s = load_surface(write_file(dir, "tet_" + format + ".ply", ply_tet(format)), &check);
    ASSERT_EQ(s.positions_World_mm.cols(), 4);
    ASSERT_EQ(s.tris.size(), 4u);
    EXPECT_EQ(s.positions_World_mm(2, 3), 1.0);
    EXPECT_EQ(s.positions_World_mm(0, 1), 1.0);
    EXPECT_NEAR(check.volume_mm3, 1.0 / 6.0, 1e-12);
    EXPECT_FALSE(check.flipped);
  }
}

TEST(SurfaceLoaders, RealSciKitSurgeryLivers) {
  SurfaceCheck check;
  const TriMesh ply = load_surface(data_meshes() + "sksurgery_liver.ply", &check);  // binary little-endian
  EXPECT_EQ(ply.positions_World_mm.cols(), 2002);
  EXPECT_EQ(ply.tris.size(), 4000u);
  EXPECT_EQ(check.components, 1);
  EXPECT_GT(check.volume_mm3, 0.5e6);  // a real liver, mm
  const Eigen::Vector3d ext = ply.positions_World_mm.rowwise().maxCoeff() - ply.positions_World_mm.rowwise().minCoeff();
  EXPECT_NEAR(ext.x(), 232.0, 2.0);  // about 232 x 154 x 168 mm (data/README.md)
  EXPECT_NEAR(ext.y(), 154.0, 2.0);
  EXPECT_NEAR(ext.z(), 168.0, 2.0);
  const TriMesh fine = load_surface(data_meshes() + "sksurgery_liver_fine.vtk", &check);
  EXPECT_EQ(fine.tris.size(), 20000u);
  EXPECT_EQ(check.components, 6);  // one liver and 5 tiny blobs inside
}

TEST(SurfaceLoaders, PlyErrorsNameLineOrByteOffsetAndFix) {
  const std::string dir = scratch("ply_bad");
  const std::string good = ply_tet("ascii");
  const std::string bin = ply_tet("binary_little_endian");
  struct Case {
    std::string name, text, expect;
  } cases[] = {
      {"notply.ply", "plx\n", ".ply:1: not a PLY file"},
      {"noend.ply", "ply\nformat ascii 1.0\nelement vertex 0\n", "no end_header"},
      {"fmt.ply", "ply\nformat binary_middle_endian 1.0\nend_header\n", "fmt.ply:2: unknown PLY format"},
      {"type.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n", "type.ply:4: unknown property type"},
      {"count.ply", "ply\nformat ascii 1.0\nelement vertex -3\nend_header\n", "count.ply:3: bad element count"},
      {"noface.ply", "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nend_header\n", "no vertex or no face element"},
      {"value.ply", [&] { std::string t = good; t.replace(t.find("1.000000 0.000000 0.000000"), 8, "1.0zz000"); return t; }(),
       "value.ply:17:"},
      {"index.ply", [&] { std::string t = good; t.replace(t.find("3 1 2 3"), 7, "3 1 2 9"); return t; }(),
       "refers to vertex 9 of 4"},
      {"short.ply", bin.substr(0, bin.size() - 6), "byte offset"},
      {"long.ply", bin + "xx", "2 bytes after the last declared element"},
  };
  for (const auto& c : cases) {
    const std::string e = error_of<LoadError>([&] { load_surface(write_file(dir, c.name, c.text)); });
    SCOPED_TRACE(c.name + ": " + e);
    EXPECT_NE(e.find(c.expect), std::string::npos);
    EXPECT_NE(e.find("Fix:"), std::string::npos);
  }
}

TEST(SurfaceLoaders, BrokenSofaVtkIsRejectedWithLocationAndFix) {
  const std::string path = data_meshes() + "liver_for_test_broken.vtk";
  const std::string e = error_of<LoadError>([&] { load_surface(path); });
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
    const std::string e = error_of<LoadError>([&] { load_surface(write_file(dir, c.name, c.text)); });
    SCOPED_TRACE(e);
    EXPECT_NE(e.find(c.name), std::string::npos);
    EXPECT_NE(e.find(c.expect), std::string::npos);
    EXPECT_NE(e.find("Fix:"), std::string::npos);
  }
  // Line numbers: the open edge belongs to the face on line 5 or later.
  const std::string e = error_of<LoadError>([&] { load_surface(dir + "/open.obj"); });
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
  auto err = [&](const char* name, const std::string& text) { return error_of<LoadError>([&] { load_volume(write_file(dir, name, text)); }); };
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
  // (a huge one once overflowed an integer conversion; found by fuzz_mesh_parsers).
  write_file(dir, "r.node", "5 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 1 1\n");
  write_file(dir, "r.ele", "2 4 1\n1 1 2 3 4 0.5\n2 2 3 4 5 5888888888888888888888888888888888888888888888888888888\n");
  const TetMesh r = load_volume(dir + "/r.ele");
  EXPECT_EQ(r.region_names, (std::vector<std::string>{"region_0.5", "region_5.88888888888889e+54"}));
  write_file(dir, "bad.node", "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n");
  write_file(dir, "bad.ele", "1 4 0\n0 0 1 2 7\n");
  const std::string e = error_of<LoadError>([&] { load_volume(dir + "/bad.node"); });
  EXPECT_NE(e.find("bad.ele:2:"), std::string::npos) << e;
  EXPECT_NE(e.find("node 7"), std::string::npos) << e;
  write_file(dir, "inv.node", "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n");
  write_file(dir, "inv.ele", "1 4 0\n0 0 2 1 3\n");
  const std::string inv = error_of<LoadError>([&] { load_volume(dir + "/inv.ele"); });
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
  EXPECT_NE(error_of<LoadError>([&] { load_volume(data_meshes() + "liver.vtk"); }).find("POLYDATA"), std::string::npos);
  EXPECT_NE(error_of<LoadError>([&] { load_surface(path); }).find("UNSTRUCTURED_GRID"), std::string::npos);
}

TEST(VtkLegacy, HeaderErrors) {
  auto err = [](const std::string& text) { return error_of<LoadError>([&] { parse_vtk_legacy(text, "h.vtk"); }); };
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
