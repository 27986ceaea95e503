// Self-contact during the non-rigid fit: a U-shaped block (two prongs on a common base,
// a 5 mm slot between them) whose data (surface points and landmarks) pull the left prong
// 9 mm sideways, into the right one. Without the self-contact term the left prong passes into the right one;
// with it, no vertex crosses and the left prong stops at the right one's face. Also the
// detector alone: the two faces of a thin plate are not a contact, a crossed vertex is.
#include <gtest/gtest.h>

#include <algorithm>
#include <iostream>

#include "host/register/nonrigid_registration.hpp"
#include "host/register/self_contact.hpp"
#include "host/mesh/box_mesh.hpp"

using namespace arnav::host;

namespace {

constexpr double kSlotLo = 25.0, kSlotHi = 30.0, kBase = 10.0;
constexpr double kPull = 9.0;  // the left prong's outer face, pulled into +x: its inner face would end 4 mm inside the right prong

// 60 x 15 x 40 mm block, 5 mm cells, with the slot 25 < x < 30, z > 10 removed.
Scene u_block() {
  const TetMesh box = make_box_tet_mesh(12, 3, 8, Eigen::Vector3d(60, 15, 40));
  std::vector<std::array<int, 4>> kept;
  for (const auto& t : box.tets) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int v : t) c += box.rest_positions_World_mm.col(v) / 4.0;
    if (c.x() > kSlotLo && c.x() < kSlotHi && c.z() > kBase) continue;
    kept.push_back(t);
  }
  std::vector<int> map(static_cast<std::size_t>(box.num_vertices()), -1);
  int n = 0;
  for (const auto& t : kept)
    for (int v : t)
      if (map[static_cast<std::size_t>(v)] < 0) map[static_cast<std::size_t>(v)] = n++;
  TetMesh m;
  m.rest_positions_World_mm.resize(3, n);
  for (int v = 0; v < box.num_vertices(); ++v)
    if (map[static_cast<std::size_t>(v)] >= 0) m.rest_positions_World_mm.col(map[static_cast<std::size_t>(v)]) = box.rest_positions_World_mm.col(v);
  for (auto t : kept) {
    for (int& v : t) v = map[static_cast<std::size_t>(v)];
    m.tets.push_back(t);
  }
  m.tet_region.assign(m.tets.size(), 0);
  m.region_names = {"default"};
  m.surface_tris = boundary_faces(m);
  Scene s;
  s.problem.mesh = m;
  s.problem.region_materials = {Material{.youngs_modulus_kPa = 5.0, .poisson_ratio = 0.45}};
  s.problem.gravity_World_mm_s2.setZero();
  for (int v = 0; v < n; ++v)
    if (m.rest_positions_World_mm(2, v) < 1e-9) s.problem.fixed_vertices.push_back(v);
  s.model.kind = "corotational_fem";
  s.organ_surface.positions_World_mm = m.rest_positions_World_mm;
  s.organ_surface.tris = m.surface_tris;
  return s;
}

// Data: the left prong's outer face above z = 20 moved kPull in +x (its closest surface
// stays that face, so the correspondences pull it); the right prong's outer and top
// faces where they are.
Eigen::Matrix3Xd pulling_data(const Scene& s) {
  std::vector<Eigen::Vector3d> pts;
  const auto& x = s.problem.mesh.rest_positions_World_mm;
  for (const auto& f : s.problem.mesh.surface_tris) {
    const Eigen::Vector3d c = (x.col(f[0]) + x.col(f[1]) + x.col(f[2])) / 3.0;
    if (c.x() < 0.1 && c.z() > 20.0) pts.push_back(c + Eigen::Vector3d(kPull, 0, 0));
    else if (c.x() > kSlotHi - 0.1 && (c.x() > 59.9 || c.z() > 39.9)) pts.push_back(c);
  }
  Eigen::Matrix3Xd d(3, static_cast<Eigen::Index>(pts.size()));
  for (std::size_t i = 0; i < pts.size(); ++i) d.col(static_cast<Eigen::Index>(i)) = pts[i];
  return d;
}

// Landmarks inside the left prong's upper half (its centre line), measured kPull further
// in +x: they move the prong as a whole (surface data alone only indent the face they see).
std::vector<LandmarkPair> pulling_landmarks() {
  std::vector<LandmarkPair> lm;
  for (double z = 22.5; z <= 37.5; z += 5.0)
    for (double y : {4.0, 11.0}) {
      const Eigen::Vector3d p(12.5, y, z);
      lm.push_back({p, p + Eigen::Vector3d(kPull, 0, 0)});
    }
  return lm;
}

// Smallest gap between the prongs' facing faces: a left inner-face vertex (rest x = 25)
// against the right inner-face vertex at the same height and depth (rest x = 30).
double min_gap(const Scene& s, const Eigen::Matrix3Xd& x) {
  const auto& r = s.problem.mesh.rest_positions_World_mm;
  double gap = 1e9;
  for (int a = 0; a < x.cols(); ++a) {
    if (std::abs(r(0, a) - kSlotLo) > 1e-9 || r(2, a) <= kBase + 1e-9) continue;
    for (int b = 0; b < x.cols(); ++b)
      if (std::abs(r(0, b) - kSlotHi) < 1e-9 && (r.col(b) - r.col(a)).tail<2>().norm() < 1e-9) gap = std::min(gap, x(0, b) - x(0, a));
  }
  return gap;
}

double left_prong_max_x(const Scene& s, const Eigen::Matrix3Xd& x) {
  double mx = -1e9;
  for (int v = 0; v < x.cols(); ++v) {
    const Eigen::Vector3d r = s.problem.mesh.rest_positions_World_mm.col(v);
    if (r.x() < kSlotLo + 0.1 && r.z() > 20.0) mx = std::max(mx, x(0, v));
  }
  return mx;
}

}  // namespace

TEST(SelfContact, ThinPlateFacesAreNotAContactButACrossedVertexIs) {
  // 40 x 40 x 2 mm plate: its top and bottom faces are 2 mm apart and geodesically far.
  const TetMesh plate = make_box_tet_mesh(8, 8, 1, Eigen::Vector3d(40, 40, 2));
  const SelfContactDetector d(plate.rest_positions_World_mm, plate.surface_tris, 8.0);
  EXPECT_TRUE(d.find(plate.rest_positions_World_mm, 1.0, 8.0).empty());
  EXPECT_EQ(d.count_crossed(plate.rest_positions_World_mm, 8.0), 0);
}

TEST(SelfContact, DetectorFindsTheProngsApproachingAndCrossing) {
  const Scene s = u_block();
  const SelfContactDetector d(s.problem.mesh.rest_positions_World_mm, s.problem.mesh.surface_tris);
  EXPECT_EQ(d.count_crossed(s.problem.mesh.rest_positions_World_mm, d.exclusion_mm()), 0);
  EXPECT_TRUE(d.find(s.problem.mesh.rest_positions_World_mm, 1.0, d.exclusion_mm()).empty());
  Eigen::Matrix3Xd x = s.problem.mesh.rest_positions_World_mm;
  for (int v = 0; v < x.cols(); ++v)
    if (x(0, v) < kSlotLo + 0.1 && x(2, v) > 30.0) x(0, v) += 8.0;  // the left prong's top 3 mm into the right one
  EXPECT_GT(d.count_crossed(x, d.exclusion_mm()), 0);
  const auto cs = d.find(x, 1.0, d.exclusion_mm());
  ASSERT_FALSE(cs.empty());
  for (const auto& c : cs) EXPECT_LT(c.signed_distance_mm, c.wanted_mm);
}

TEST(SelfContact, NonrigidFitDoesNotPullOneProngThroughTheOther) {
  const Scene s = u_block();
  const Eigen::Matrix3Xd data = pulling_data(s);
  ASSERT_GT(data.cols(), 40);
  NonrigidOptions o;
  o.scene_boundary = true;  // the base is held
  o.noise_mm = 0.1;
  o.landmark_weight = 1.0;  // mN/mm per landmark and unit of data weight
  o.min_improvement = 0.001;  // the weak first levels must not end the schedule
  o.keep_fraction = 1.0;  // clean data: the pulled points are the furthest and must not be trimmed
  o.self_contact = false;
  const std::vector<LandmarkPair> lm = pulling_landmarks();
  const NonrigidResult free = register_nonrigid(s, data, lm, o);
  ASSERT_TRUE(free.accepted) << free.message;
  // Without the term the data win: the left prong ends inside the right one.
  EXPECT_GT(free.crossed_vertices, 0);
  EXPECT_GT(left_prong_max_x(s, free.x_Model_mm), kSlotHi + 1.0);
  EXPECT_LT(min_gap(s, free.x_Model_mm), -1.0);

  o.self_contact = true;
  const NonrigidResult held = register_nonrigid(s, data, lm, o);
  ASSERT_TRUE(held.accepted) << held.message;
  EXPECT_EQ(held.crossed_vertices, 0);
  // the faces meet but do not pass (the right prong yields a little: contact is mutual)
  const double gap = min_gap(s, held.x_Model_mm);
  std::cout << "gap between the prongs: " << min_gap(s, free.x_Model_mm) << " mm without self-contact (" << free.crossed_vertices
            << " vertices crossed), " << gap << " mm with it\n";
  EXPECT_GT(gap, -0.25);
  EXPECT_LT(gap, 2.0);
  // and the left prong still moved towards the data (the gap closed)
  EXPECT_GT(left_prong_max_x(s, held.x_Model_mm), kSlotLo + 3.0);
  int contacts = 0;
  for (const auto& l : held.levels) contacts = std::max(contacts, l.contacts);
  EXPECT_GT(contacts, 0);
}
