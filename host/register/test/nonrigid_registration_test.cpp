// Non-rigid registration through the tissue model: a deformed liver (pressed and pulled,
// with a heterogeneous material the registration does not know) seen through a partial
// surface with outliers and a rigid offset; the non-rigid result must beat the rigid one
// on interior targets, keep the rigid result when the data cannot support a deformation,
// and run with every tissue model kind.
#include <gtest/gtest.h>

#include <cstdlib>
#include <random>

#include "host/register/registration.hpp"
#include "host/register/synthetic_data.hpp"
#include "host/scene/scene.hpp"
#include "host/sim/model_factory.hpp"

using namespace arnav::host;

namespace {

const Scene& coarse_scene() {
  static const Scene s = [] {
    const char* d = std::getenv("ARNAV_DATA_DIR");
    if (!d) throw std::runtime_error("ARNAV_DATA_DIR is not set");
    return load_scene(std::string(d) + "/liver/liver_coarse.scene.yaml");
  }();
  return s;
}

struct Case {
  Eigen::Matrix3Xd deformed;          // truth volume positions (Model)
  Eigen::Matrix3Xd targets_rest, targets_truth_Intraop;
  Eigen::Matrix3Xd data_Intraop;
  std::vector<Landmark> landmarks;
  Eigen::Isometry3d X_true;
};

// Truth: the same mesh with a stiffer and a softer half (the registration assumes the
// scene's uniform material), a tool pressing 15 mm into the front and the lower lobe
// pulled 20 mm, solved to equilibrium.
Case make_case(unsigned seed) {
  const Scene& s = coarse_scene();
  SimProblem p = s.problem;
  p.gravity_World_mm_s2.setZero();
  Material soft = p.region_materials[0], stiff = soft;
  soft.youngs_modulus_kPa = 3.5;
  stiff.youngs_modulus_kPa = 9.0;
  p.region_materials.push_back(soft);
  p.region_materials.push_back(stiff);
  const int first = static_cast<int>(p.region_materials.size()) - 2;
  const double xmid = p.mesh.rest_positions_World_mm.row(0).mean();
  for (int t = 0; t < p.mesh.num_tets(); ++t) {
    if (p.mesh.tet_region[static_cast<std::size_t>(t)] != 0) continue;
    const double cx = p.mesh.rest_positions_World_mm.col(p.mesh.tets[static_cast<std::size_t>(t)][0]).x();
    p.mesh.tet_region[static_cast<std::size_t>(t)] = first + (cx < xmid ? 0 : 1);
  }
  ModelConfig c;
  c.kind = "corotational_fem";
  c.integrator = "implicit_euler";
  c.linear_solver = "cholmod";
  auto model = make_tissue_model(p, c);
  const Eigen::Vector3d view(0, -1, 0);
  Eigen::Index front = 0;
  (s.organ_surface.positions_World_mm.transpose() * view).maxCoeff(&front);
  const Eigen::Vector3d press_centre = s.organ_surface.positions_World_mm.col(front);
  struct Pull {
    AttachmentId id;
    Eigen::Vector3d from, to;
  };
  std::vector<Pull> pulls;
  for (int v = 0; v < s.organ_surface.positions_World_mm.cols(); ++v) {
    const Eigen::Vector3d x0 = s.organ_surface.positions_World_mm.col(v);
    if ((x0 - press_centre).norm() < 15.0)
      pulls.push_back({model->add_attachment({s.organ_embedding.material_point(s.problem.mesh, v), x0, 20.0}), x0, x0 - 15.0 * view});
  }
  for (int v : lowest_surface_patch(s, 15.0)) {
    const Eigen::Vector3d x0 = s.organ_surface.positions_World_mm.col(v);
    pulls.push_back({model->add_attachment({s.organ_embedding.material_point(s.problem.mesh, v), x0, 20.0}), x0, x0 + Eigen::Vector3d(20, 0, 0)});
  }
  const Eigen::Matrix3Xd zero = Eigen::Matrix3Xd::Zero(3, p.mesh.num_vertices());
  for (int it = 0; it < 60; ++it) {
    const double f = std::min(1.0, (it + 1) / 5.0);
    for (const auto& pl : pulls) model->set_attachment_target(pl.id, pl.from + f * (pl.to - pl.from));
    const StepSummary st = model->step(0.2);
    if (!st.healthy) throw std::runtime_error("truth solve failed: " + st.warning);
    model->set_state(model->positions_World_mm(), zero);
  }
  Case k;
  k.deformed = model->positions_World_mm();
  std::mt19937 rng(seed);
  // 30 interior targets: tet centroids
  std::uniform_int_distribution<int> pick(0, s.problem.mesh.num_tets() - 1);
  k.targets_rest.resize(3, 30);
  Eigen::Matrix3Xd targets_truth(3, 30);
  for (int i = 0; i < 30; ++i) {
    const auto& t = s.problem.mesh.tets[static_cast<std::size_t>(pick(rng))];
    k.targets_rest.col(i).setZero();
    targets_truth.col(i).setZero();
    for (int v : t) {
      k.targets_rest.col(i) += s.problem.mesh.rest_positions_World_mm.col(v) / 4.0;
      targets_truth.col(i) += k.deformed.col(v) / 4.0;
    }
  }
  const Eigen::Matrix3Xd surface = s.organ_embedding.apply(s.problem.mesh, k.deformed);
  SampledPatch patch = sample_patch(surface, s.organ_surface.tris, surface.col(front), view, 0.35, 4.0, rng);
  Eigen::Matrix3Xd data = patch.points_mm;
  add_noise(data, 0.5, rng);
  add_outliers(data, surface, 0.05, 20.0, 5.0, rng);
  k.X_true = random_rigid(25.0, 100.0, rng);
  k.data_Intraop = k.X_true * data;
  k.targets_truth_Intraop = k.X_true * targets_truth;
  for (int axis = 0; axis < 3; ++axis) {
    Eigen::Index i = 0;
    s.organ_surface.positions_World_mm.row(axis).maxCoeff(&i);
    k.landmarks.push_back({"l" + std::to_string(axis), s.organ_surface.positions_World_mm.col(i), k.X_true * surface.col(i) + Eigen::Vector3d(1, -1, 1), 0});
  }
  return k;
}

double mean_tre(const Eigen::Matrix3Xd& predicted, const Eigen::Matrix3Xd& truth) { return (predicted - truth).colwise().norm().mean(); }

}  // namespace

class NonrigidMethod : public ::testing::TestWithParam<std::string> {};
INSTANTIATE_TEST_SUITE_P(Methods, NonrigidMethod, ::testing::Values("loads", "energy"));

TEST_P(NonrigidMethod, BeatsRigidOnInteriorTargets) {
  const Scene& s = coarse_scene();
  const Case k = make_case(11);
  const double deformation = (k.deformed - s.problem.mesh.rest_positions_World_mm).colwise().norm().maxCoeff();
  ASSERT_GT(deformation, 8.0);
  RegistrationRequest rq;
  rq.points_Intraop_mm = k.data_Intraop;
  rq.landmarks = k.landmarks;
  rq.nonrigid.noise_mm = 0.4;
  rq.nonrigid_method = GetParam();
  const RegistrationResult r = register_patient(s, rq);
  const Embedding e = embed_points(s.problem.mesh, k.targets_rest, 0.5, "target");
  const double rigid = mean_tre(r.icp.X_IntraopModel * k.targets_rest, k.targets_truth_Intraop);  // the surface-rigid result
  const double nonrigid = mean_tre(carry_to_intraop(s, e, r), k.targets_truth_Intraop);
  std::cout << GetParam() << ": max deformation " << deformation << " mm; mean TRE rigid " << rigid << " mm, non-rigid " << nonrigid << " mm, "
            << r.nonrigid->message << ", " << r.nonrigid->wall_time_s << " s\n";
  ASSERT_TRUE(r.nonrigid);
  EXPECT_TRUE(r.deformed) << r.nonrigid->message;
  EXPECT_LT(r.nonrigid->final_rms_mm, r.nonrigid->rigid_rms_mm);
  EXPECT_LT(nonrigid, 0.8 * rigid);
  ASSERT_FALSE(r.nonrigid->levels.empty());
  EXPECT_GT(r.nonrigid->levels.front().points_trimmed, 0);  // the outliers
  EXPECT_LT(r.nonrigid->inverted_elements, s.problem.mesh.num_tets() / 200) << "inverted elements";  // under 0.5 %
  if (GetParam() == "loads") {
    ASSERT_TRUE(r.loads);
    EXPECT_GT(r.basis_modes, 100);
    EXPECT_FALSE(r.X_IntraopModel.isApprox(r.icp.X_IntraopModel));  // the pose was estimated with the loads
  }
}

TEST_P(NonrigidMethod, AllOutliersKeepTheRigidResult) {
  const Scene& s = coarse_scene();
  const Case k = make_case(12);
  std::mt19937 rng(5);
  Eigen::Matrix3Xd far = Eigen::Matrix3Xd::Zero(3, 0);
  // points 40-80 mm away from the organ, around it
  Eigen::Matrix3Xd junk(3, 300);
  std::uniform_real_distribution<double> u(-1, 1);
  const Eigen::Vector3d c = s.organ_surface.positions_World_mm.rowwise().mean();
  for (int i = 0; i < 300; ++i) junk.col(i) = c + Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized() * (180.0 + 40.0 * u(rng));
  RegistrationRequest rq;
  rq.points_Intraop_mm = k.X_true * junk;
  rq.landmarks = k.landmarks;
  rq.nonrigid_method = GetParam();
  const RegistrationResult r = register_patient(s, rq);
  ASSERT_TRUE(r.nonrigid);
  EXPECT_FALSE(r.deformed);
  EXPECT_NE(r.nonrigid->message.find("data does not support a non-rigid fit"), std::string::npos) << r.nonrigid->message;
  EXPECT_TRUE(r.x_Model_mm.isApprox(s.problem.mesh.rest_positions_World_mm));
}

TEST_P(NonrigidMethod, EmptyCloudKeepsTheLandmarkPose) {
  const Scene& s = coarse_scene();
  const Case k = make_case(13);
  RegistrationRequest rq;
  rq.points_Intraop_mm = Eigen::Matrix3Xd(3, 0);
  rq.landmarks = k.landmarks;
  rq.nonrigid_method = GetParam();
  const RegistrationResult r = register_patient(s, rq);
  EXPECT_FALSE(r.deformed);
  EXPECT_TRUE(r.X_IntraopModel.isApprox(r.landmarks->X_IntraopModel));
  EXPECT_NE(r.nonrigid->message.find("data does not support"), std::string::npos);
}

// Every model kind in this build runs the energy method's non-rigid stage; whatever it
// reaches, the result is never worse than the rigid one on the data. (The loads method
// does not step a model: its basis is the linear elastic response of the scene's mesh
// and materials, the same for every kind.)
TEST(NonrigidRegistration, EveryModelKindNeverWorseThanRigid) {
  const Scene& s = coarse_scene();
  const Case k = make_case(14);
  for (const std::string& kind : available_model_kinds()) {
    RegistrationRequest rq;
    rq.points_Intraop_mm = k.data_Intraop;
    rq.landmarks = k.landmarks;
    rq.nonrigid_method = "energy";
    rq.nonrigid.model_kind = kind;
    rq.nonrigid.noise_mm = 0.4;
    rq.nonrigid.data_weight_schedule = {4, 64};
    const RegistrationResult r = register_patient(s, rq);
    ASSERT_TRUE(r.nonrigid);
    std::cout << kind << ": " << r.nonrigid->message << ", rms " << r.nonrigid->rigid_rms_mm << " -> " << r.nonrigid->final_rms_mm << " mm, "
              << r.nonrigid->wall_time_s << " s\n";
    if (r.deformed) {
      EXPECT_LT(r.nonrigid->final_rms_mm, r.nonrigid->rigid_rms_mm) << kind;
    } else {
      EXPECT_TRUE(r.x_Model_mm.isApprox(s.problem.mesh.rest_positions_World_mm)) << kind;
    }
  }
  EXPECT_THROW(
      {
        RegistrationRequest rq;
        rq.points_Intraop_mm = k.data_Intraop;
        rq.nonrigid_method = "energy";
        rq.nonrigid.model_kind = "rubber";
        register_patient(s, rq);
      },
      std::invalid_argument);
  EXPECT_THROW(
      {
        RegistrationRequest rq;
        rq.points_Intraop_mm = k.data_Intraop;
        rq.nonrigid_method = "magic";
        register_patient(s, rq);
      },
      std::invalid_argument);
}
