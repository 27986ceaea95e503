// Blade, swept surface, segment/point-triangle queries, BVH against brute force, contact.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>
#include <set>

#include "host/cut/blade.hpp"
#include "host/cut/bvh.hpp"
#include "host/mesh/box_mesh.hpp"

using namespace arnav::host;
using namespace arnav::host::cut;

TEST(Blade, PoseMovesTipAndHeel) {
  Blade blade{Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0, 0, 30)};
  Eigen::Isometry3d X_World_Tool = Eigen::Isometry3d::Identity();
  X_World_Tool.linear() = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX()).toRotationMatrix();
  X_World_Tool.translation() = Eigen::Vector3d(10, 20, 30);
  const BladeSegment s = blade_in_world(blade, X_World_Tool);
  EXPECT_NEAR((s.tip_World_mm - Eigen::Vector3d(10, 20, 30)).norm(), 0.0, 1e-12);
  EXPECT_NEAR((s.heel_World_mm - Eigen::Vector3d(10, -10, 30)).norm(), 0.0, 1e-12);
}

TEST(SweptSurface, PlanarSweepIsExactTwistedReportsDeviation) {
  SweptSurface planar{{Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0, 0, 10)}, {Eigen::Vector3d(5, 0, 0), Eigen::Vector3d(5, 0, 10)}, 1, {}};
  EXPECT_EQ(planar.triangles().size(), 2u);
  EXPECT_NEAR(planar.max_deviation_mm(), 0.0, 1e-12);
  double area = 0;
  for (const auto& t : planar.triangles()) area += 0.5 * (t.b - t.a).cross(t.c - t.a).norm();
  EXPECT_NEAR(area, 50.0, 1e-12);
  // A twisting blade: the bilinear patch is not planar; more strips, smaller deviation.
  SweptSurface twisted{{Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0, 0, 10)}, {Eigen::Vector3d(5, 0, 0), Eigen::Vector3d(5, 4, 10)}, 1, {}};
  const double d1 = twisted.max_deviation_mm();
  twisted.strips = 8;
  EXPECT_GT(d1, 0.1);
  EXPECT_LT(twisted.max_deviation_mm(), d1 / 4);
  SweptSurface still{planar.from, planar.from, 1, {}};
  EXPECT_TRUE(still.degenerate());
  EXPECT_FALSE(planar.degenerate());
}

TEST(Geometry, SegmentTriangle) {
  const Triangle t{Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(10, 0, 0), Eigen::Vector3d(0, 10, 0)};
  double s = -1;
  ASSERT_TRUE(segment_triangle_intersection(Eigen::Vector3d(2, 2, -1), Eigen::Vector3d(2, 2, 3), t, s));
  EXPECT_NEAR(s, 0.25, 1e-14);
  EXPECT_FALSE(segment_triangle_intersection(Eigen::Vector3d(8, 8, -1), Eigen::Vector3d(8, 8, 3), t, s));  // outside
  EXPECT_FALSE(segment_triangle_intersection(Eigen::Vector3d(2, 2, 1), Eigen::Vector3d(2, 2, 3), t, s));   // above
  EXPECT_FALSE(segment_triangle_intersection(Eigen::Vector3d(1, 1, 0), Eigen::Vector3d(3, 1, 0), t, s));   // in plane
  ASSERT_TRUE(segment_triangle_intersection(Eigen::Vector3d(5, 0, -1), Eigen::Vector3d(5, 0, 1), t, s));   // on an edge
  EXPECT_NEAR(s, 0.5, 1e-14);
  ASSERT_TRUE(segment_triangle_intersection(Eigen::Vector3d(1, 1, 0), Eigen::Vector3d(1, 1, 4), t, s));    // touching end
  EXPECT_NEAR(s, 0.0, 1e-14);
}

TEST(Geometry, PointTriangleDistanceAgainstSampling) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-5, 5);
  for (int trial = 0; trial < 200; ++trial) {
    const Triangle t{Eigen::Vector3d(u(rng), u(rng), u(rng)), Eigen::Vector3d(u(rng), u(rng), u(rng)), Eigen::Vector3d(u(rng), u(rng), u(rng))};
    const Eigen::Vector3d p(u(rng), u(rng), u(rng));
    Eigen::Vector3d q;
    const double d = point_triangle_distance(p, t, &q);
    double best = 1e300;
    const int n = 200;
    for (int i = 0; i <= n; ++i)
      for (int j = 0; i + j <= n; ++j) {
        const Eigen::Vector3d s = t.a + (t.b - t.a) * i / n + (t.c - t.a) * j / n;
        best = std::min(best, (p - s).norm());
      }
    EXPECT_LE(d, best + 1e-12);
    EXPECT_GT(d, best - 0.1);  // sampling resolution
    EXPECT_NEAR((p - q).norm(), d, 1e-12);
  }
}

TEST(Bvh, QueryMatchesBruteForceAfterRefit) {
  TetMesh mesh = make_box_tet_mesh(6, 5, 4, Eigen::Vector3d(60, 50, 40));
  Eigen::Matrix3Xd x = mesh.rest_positions_World_mm;
  const auto& tris = mesh.surface_tris;
  Bvh bvh;
  bvh.build(triangle_boxes(tris, x));
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-10, 70);
  for (int round = 0; round < 3; ++round) {
    // Deform (a bend), refit, compare with brute force.
    for (int i = 0; i < x.cols(); ++i) x(2, i) = mesh.rest_positions_World_mm(2, i) + round * 0.01 * x(0, i) * x(0, i);
    bvh.refit(triangle_boxes(tris, x));
    const auto boxes = triangle_boxes(tris, x);
    for (int q = 0; q < 50; ++q) {
      Aabb box;
      box.extend(Eigen::Vector3d(u(rng), u(rng), u(rng)));
      box.extend(Eigen::Vector3d(u(rng), u(rng), u(rng)));
      std::set<int> found, expected;
      bvh.query(box, [&](int i) { found.insert(i); });
      for (std::size_t i = 0; i < boxes.size(); ++i)
        if (boxes[i].overlaps(box)) expected.insert(static_cast<int>(i));
      EXPECT_EQ(found, expected);
    }
  }
}

TEST(Contact, BladeIntoBoxReportsEntryTriangleAndDepth) {
  TetMesh mesh = make_box_tet_mesh(4, 4, 4, Eigen::Vector3d(40, 40, 40));
  Eigen::Matrix3Xd x = mesh.rest_positions_World_mm;
  Bvh bvh;
  bvh.build(triangle_boxes(mesh.surface_tris, x));
  // Blade pushed 7 mm into the top face (z = 40), tip first.
  const Contact c = blade_contact(bvh, mesh.surface_tris, x, {Eigen::Vector3d(13, 17, 33), Eigen::Vector3d(13, 17, 60)});
  ASSERT_TRUE(c.touching);
  EXPECT_TRUE(c.tip_inside);
  EXPECT_NEAR(c.depth_mm, 7.0, 1e-12);
  EXPECT_NEAR((c.point_World_mm - Eigen::Vector3d(13, 17, 40)).norm(), 0.0, 1e-12);
  const auto& tri = mesh.surface_tris[static_cast<std::size_t>(c.triangle)];
  for (int v : tri) EXPECT_NEAR(x(2, v), 40.0, 1e-12);
  // After the box is lifted by 5 mm (refit), the same blade is 12 mm deep.
  x.row(2).array() += 5.0;
  bvh.refit(triangle_boxes(mesh.surface_tris, x));
  EXPECT_NEAR(blade_contact(bvh, mesh.surface_tris, x, {Eigen::Vector3d(13, 17, 33), Eigen::Vector3d(13, 17, 60)}).depth_mm, 12.0, 1e-12);
  // A blade beside the organ touches nothing.
  EXPECT_FALSE(blade_contact(bvh, mesh.surface_tris, x, {Eigen::Vector3d(-5, 17, 33), Eigen::Vector3d(-5, 17, 60)}).touching);
  // Through the whole organ: enters and leaves, tip outside, no depth.
  const Contact through = blade_contact(bvh, mesh.surface_tris, x, {Eigen::Vector3d(13, 17, -10), Eigen::Vector3d(13, 17, 60)});
  EXPECT_TRUE(through.touching);
  EXPECT_FALSE(through.tip_inside);
  EXPECT_NEAR(through.point_World_mm.z(), 45.0, 1e-12);
}
