// Load-basis registration (load_basis.hpp): the basis is the linear elastic response to
// generic loads, and the fit recovers a deformation from partial surface data.
//  - Analytic: a bar (nu = 0) clamped at x = 0 and pulled by a uniform traction on its far
//    end; the exact solution is the uniform stretch u_x = delta x / L (linear tets represent
//    it exactly). Seen only through its top face and the loaded end (no data on the other
//    faces), the fit must recover the interior displacement along the whole bar.
//  - The basis spans the whole surface (every surface vertex outside the support is in a
//    patch), has gravity and support modes, a symmetric positive definite energy metric.
//  - Bad inputs: a basis of another mesh, a degenerate tet, a material missing, an empty
//    cloud; a scene without support (the rigid part of the modes is removed).
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include <random>
#include <stdexcept>

#include "host/register/load_basis.hpp"
#include "host/scene/box_mesh.hpp"

using namespace arnav::host;

namespace {

constexpr int kNx = 10, kNy = 2, kNz = 2;
const Eigen::Vector3d kSize(100, 20, 20);

Scene bar(bool clamped) {
  Scene s;
  s.problem.mesh = make_box_tet_mesh(kNx, kNy, kNz, kSize);
  s.problem.mesh.tet_region.assign(s.problem.mesh.tets.size(), 0);
  s.problem.mesh.region_names = {"default"};
  s.problem.region_materials = {Material{.youngs_modulus_kPa = 5.0, .poisson_ratio = 0.0}};
  s.problem.gravity_World_mm_s2.setZero();
  if (clamped)
    for (int v = 0; v < s.problem.mesh.num_vertices(); ++v)
      if (s.problem.mesh.rest_positions_World_mm(0, v) < 1e-9) s.problem.fixed_vertices.push_back(v);
  s.organ_surface.positions_World_mm = s.problem.mesh.rest_positions_World_mm;
  s.organ_surface.tris = s.problem.mesh.surface_tris;
  return s;
}

// Exact uniaxial solution of the clamped bar (nu = 0) under an end traction: tip displacement delta.
Eigen::Vector3d stretched(const Eigen::Vector3d& p, double delta) { return p + Eigen::Vector3d(delta * p.x() / kSize.x(), 0, 0); }

}  // namespace

TEST(LoadBasis, CoversTheWholeSurfaceWithASymmetricEnergyMetric) {
  const Scene s = bar(true);
  LoadBasisOptions o;
  o.patches = 12;
  o.support_clusters = 2;
  const LoadBasis b = build_load_basis(s, o);
  EXPECT_EQ(b.patches, 12);
  EXPECT_EQ(b.gravity, 3);
  EXPECT_EQ(b.support, 3);  // the second part relative to the first
  EXPECT_EQ(b.modes(), 3 * 12 + 3 + 3);
  EXPECT_TRUE(b.supported);
  // every surface vertex outside the support belongs to a patch; fixed ones do not
  std::vector<char> fixed(static_cast<std::size_t>(s.problem.mesh.num_vertices()), 0);
  for (int v : s.problem.fixed_vertices) fixed[static_cast<std::size_t>(v)] = 1;
  for (const auto& f : s.problem.mesh.surface_tris)
    for (int v : f) EXPECT_EQ(b.patch_of_vertex[static_cast<std::size_t>(v)] >= 0, !fixed[static_cast<std::size_t>(v)]) << v;
  // force modes leave the support where it is; the metric is symmetric positive definite
  for (int j = 0; j < 3 * b.patches + b.gravity; ++j)
    for (int v : s.problem.fixed_vertices) EXPECT_LT(b.U.block(3 * v, j, 3, 1).norm(), 1e-12);
  EXPECT_LT((b.G - b.G.transpose()).norm(), 1e-9 * b.G.norm());
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(b.G);
  EXPECT_GT(eig.eigenvalues().minCoeff(), 0.0);
  // a support mode translates its part of the support (all by the same amount, along its
  // axis) and holds the rest of it
  for (int j = 3 * b.patches + b.gravity; j < b.modes(); ++j) {
    const int axis = j % 3;  // modes come in x, y, z triples
    double moved = 0;
    int moving = 0;
    for (int v : s.problem.fixed_vertices) {
      const Eigen::Vector3d d = b.U.block(3 * v, j, 3, 1);
      if (d.norm() < 1e-12) continue;
      ++moving;
      if (moved == 0) moved = d[axis];
      EXPECT_NEAR(d[axis], moved, 1e-12);
      EXPECT_NEAR(d.norm(), std::abs(d[axis]), 1e-12);
    }
    EXPECT_GT(moving, 0) << b.mode_kind[static_cast<std::size_t>(j)];
    EXPECT_LT(moving, static_cast<int>(s.problem.fixed_vertices.size())) << b.mode_kind[static_cast<std::size_t>(j)];
  }
}

TEST(LoadBasis, RecoversABarUnderAnEndLoadFromItsTopFaceAndEnd) {
  const Scene s = bar(true);
  const double delta = 5.0;  // tip displacement (mm): traction E delta / L = 0.25 kPa
  // Data: the deformed top face (z = 20) and the loaded end (x = 100), every 2.5 mm; the
  // bottom, the sides and the clamped end are not seen (about 40 % of the surface).
  std::vector<Eigen::Vector3d> pts;
  for (double x = 0.0; x <= 100.0; x += 2.5)
    for (double y = 0.0; y <= 20.0; y += 2.5) pts.push_back(stretched(Eigen::Vector3d(x, y, 20.0), delta));
  for (double y = 0.0; y <= 20.0; y += 2.5)
    for (double z = 0.0; z < 20.0; z += 2.5) pts.push_back(stretched(Eigen::Vector3d(100.0, y, z), delta));
  Eigen::Matrix3Xd data(3, static_cast<Eigen::Index>(pts.size()));
  for (std::size_t i = 0; i < pts.size(); ++i) data.col(static_cast<Eigen::Index>(i)) = pts[i];
  LoadBasisOptions bo;
  bo.patches = 16;
  const LoadBasis b = build_load_basis(s, bo);
  LoadFitOptions fo;
  fo.noise_mm = 0.02;       // noise-free data: fit to the discretisation level
  fo.estimate_pose = false; // a translation along x would look like the stretch from these faces
  fo.keep_fraction = 1.0;
  const LoadFitResult r = fit_load_basis(s, b, data, fo);
  ASSERT_TRUE(r.accepted) << r.message;
  EXPECT_LT(r.final_rms_mm, 0.1);
  // Interior (axis) and all vertices against the exact solution.
  double worst = 0.0, rigid_worst = 0.0, sum = 0.0, axis_worst = 0.0;
  for (int v = 0; v < s.problem.mesh.num_vertices(); ++v) {
    const Eigen::Vector3d p = s.problem.mesh.rest_positions_World_mm.col(v);
    const double e = (r.x_Model_mm.col(v) - stretched(p, delta)).norm();
    worst = std::max(worst, e);
    sum += e;
    if (std::abs(p.y() - 10.0) < 1e-9 && std::abs(p.z() - 10.0) < 1e-9) axis_worst = std::max(axis_worst, e);
    rigid_worst = std::max(rigid_worst, (p - stretched(p, delta)).norm());
  }
  for (const auto& it : r.iterations)
    std::cout << "  rms " << it.rms_mm << " predicted " << it.predicted_rms_mm << " lambda " << it.lambda << " step " << it.step_shape_mm << "\n";
  const double mean = sum / s.problem.mesh.num_vertices();
  std::cout << "bar: vertex error mean " << mean << " mm, on the axis at most " << axis_worst << " mm, worst " << worst << " mm (rigid " << rigid_worst << " mm), " << r.iterations.size() << " iterations, "
            << r.message << "\n";
  EXPECT_NEAR(rigid_worst, delta, 1e-9);
  EXPECT_LT(mean, 0.05 * delta);
  EXPECT_LT(axis_worst, 0.1 * delta);  // the patches (Euclidean clusters) do not follow the end face exactly
  EXPECT_LT(worst, 0.15 * delta);  // unseen faces (bottom, sides) are left to the regularisation
  // the pose was not touched
  EXPECT_TRUE(r.D.isApprox(Eigen::Isometry3d::Identity()));
}

TEST(LoadBasis, NoDeformationWhenTheDataFitTheRestShape) {
  const Scene s = bar(true);
  const LoadBasis b = build_load_basis(s, {});
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, 0.5);
  Eigen::Matrix3Xd data(3, 0);
  std::vector<Eigen::Vector3d> pts;
  for (double x = 0.0; x <= 100.0; x += 2.5)
    for (double y = 0.0; y <= 20.0; y += 2.5) pts.push_back(Eigen::Vector3d(x, y, 20.0 + n(rng)));
  data.resize(3, static_cast<Eigen::Index>(pts.size()));
  for (std::size_t i = 0; i < pts.size(); ++i) data.col(static_cast<Eigen::Index>(i)) = pts[i];
  LoadFitOptions fo;
  fo.noise_mm = 0.5;
  const LoadFitResult r = fit_load_basis(s, b, data, fo);
  // noise at the expected level: the rigid fit already explains the data
  EXPECT_FALSE(r.accepted) << r.message;
  EXPECT_TRUE(r.x_Model_mm.isApprox(s.problem.mesh.rest_positions_World_mm));
}

TEST(LoadBasis, BadInputs) {
  const Scene s = bar(true);
  const LoadBasis b = build_load_basis(s, {});
  // a basis built for another mesh
  Scene other = s;
  other.problem.mesh = make_box_tet_mesh(4, 2, 2, kSize);
  other.problem.mesh.tet_region.assign(other.problem.mesh.tets.size(), 0);
  EXPECT_THROW(fit_load_basis(other, b, Eigen::Matrix3Xd::Zero(3, 30), {}), std::invalid_argument);
  // a tet without a material
  Scene nomat = s;
  nomat.problem.mesh.tet_region[5] = 3;
  try {
    build_load_basis(nomat, {});
    ADD_FAILURE() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("tet 5"), std::string::npos) << e.what();
  }
  // a degenerate (flat) tet
  Scene flat = s;
  const auto t = flat.problem.mesh.tets[7];
  flat.problem.mesh.rest_positions_World_mm.col(t[3]) = flat.problem.mesh.rest_positions_World_mm.col(t[0]);
  EXPECT_THROW(build_load_basis(flat, {}), std::invalid_argument);
  // an empty cloud and a cloud far away: the rigid result is kept, with the reason
  for (const Eigen::Matrix3Xd& d : {Eigen::Matrix3Xd(3, 0), Eigen::Matrix3Xd(Eigen::Matrix3Xd::Constant(3, 50, 500.0))}) {
    const LoadFitResult r = fit_load_basis(s, b, d, {});
    EXPECT_FALSE(r.accepted);
    EXPECT_NE(r.message.find("data does not support a non-rigid fit"), std::string::npos) << r.message;
    EXPECT_TRUE(r.x_Model_mm.isApprox(s.problem.mesh.rest_positions_World_mm));
  }
}

TEST(LoadBasis, UnsupportedSceneHasNoRigidPartInItsModes) {
  const Scene s = bar(false);
  LoadBasisOptions o;
  o.patches = 8;
  const LoadBasis b = build_load_basis(s, o);
  EXPECT_FALSE(b.supported);
  EXPECT_EQ(b.support, 0);
  // no translation left in any mode (mean displacement about 0 against its 1 mm scale)
  for (int j = 0; j < b.modes(); ++j) {
    const Eigen::VectorXd u = b.U.col(j);
    const Eigen::Vector3d mean = Eigen::Map<const Eigen::Matrix3Xd>(u.data(), 3, s.problem.mesh.num_vertices()).rowwise().mean();
    EXPECT_LT(mean.norm(), 1e-6) << b.mode_kind[static_cast<std::size_t>(j)];
  }
}
