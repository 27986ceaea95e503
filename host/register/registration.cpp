#include "host/register/registration.hpp"

#include <chrono>
#include <stdexcept>

#include "calibration/lib/point_registration.hpp"

namespace arnav::host {
namespace {

// The start's prior: a given pose (file or identity) with the isotropic uncertainty, else
// the landmark fit's covariance; none without either.
std::optional<PosePrior> make_prior(const Scene& scene, const RegistrationRequest& rq, const RegistrationResult& r) {
  const Eigen::Vector3d centre = scene.problem.mesh.rest_positions_World_mm.rowwise().mean();
  if (rq.X_IntraopModel_initial)
    return isotropic_pose_prior(*rq.X_IntraopModel_initial, centre, rq.prior.rotation_deg, rq.prior.translation_mm, r.initialisation);
  if (r.landmarks)
    return landmark_pose_prior(rq.landmarks, r.landmarks->X_IntraopModel, r.landmarks->fit.fre_rms_mm, centre, rq.prior.landmark_error_mm);
  return std::nullopt;
}

}  // namespace

RegistrationResult register_patient(const Scene& scene, const RegistrationRequest& rq) {
  const auto t0 = std::chrono::steady_clock::now();
  RegistrationResult r;
  r.x_Model_mm = scene.problem.mesh.rest_positions_World_mm;
  Eigen::Isometry3d start = Eigen::Isometry3d::Identity();
  r.initialisation = "identity";
  if (!rq.landmarks.empty()) {
    r.landmarks = register_landmarks(rq.landmarks);
    start = r.landmarks->X_IntraopModel;
    r.initialisation = "landmarks";
  }
  if (rq.X_IntraopModel_initial) {
    start = *rq.X_IntraopModel_initial;
    r.initialisation = rq.initial_pose_name.empty() ? "initial pose" : rq.initial_pose_name;
  }
  r.X_IntraopModel = start;
  r.kept_reason = "no stage changed the " + r.initialisation + " pose";
  if (rq.prior.enabled) r.prior = make_prior(scene, rq, r);
  if (rq.estimate_noise) {
    const double est = estimate_point_noise_mm(rq.points_Intraop_mm);
    r.noise_estimated = est > 0;
    r.noise_mm = std::max(rq.min_estimated_noise_mm, est > 0 ? est : rq.nonrigid.noise_mm);
    r.notes.push_back("point noise estimated from the data (distance to the local plane of 16 neighbours): " + std::to_string(est) + " mm; used " +
                      std::to_string(r.noise_mm) + " mm");
  } else {
    r.noise_mm = rq.nonrigid.noise_mm;
  }
  IcpOptions icp_options = rq.icp;
  if (icp_options.noise_mm <= 0) icp_options.noise_mm = r.noise_mm;
  r.icp = icp_point_to_plane(scene.organ_surface.positions_World_mm, scene.organ_surface.tris, rq.points_Intraop_mm, rq.normals_Intraop,
                             start, icp_options, r.prior ? &*r.prior : nullptr);
  r.posterior = r.icp.posterior;
  if (r.icp.summary.termination == "no data") {
    r.notes.push_back("no surface points: the rigid result is the " + r.initialisation + " pose");
  } else if (r.icp.summary.termination.rfind("too few inliers", 0) == 0 || r.icp.summary.termination == "numerical failure") {
    r.notes.push_back("surface ICP failed (" + r.icp.summary.termination + "): the rigid result is the " + r.initialisation + " pose");
    r.kept_reason = "surface ICP failed (" + r.icp.summary.termination + ")";
  } else if (r.icp.start_kept) {
    r.notes.push_back("surface rigid: not supported against the " + r.prior->source + " prior: " + r.icp.start_kept_reason + "; the " +
                      r.initialisation + " pose is kept");
    r.kept_reason = "the surface-rigid pose was not supported against the prior: " + r.icp.start_kept_reason;
  } else {
    r.X_IntraopModel = r.icp.X_IntraopModel;
    r.kept_stage = "surface_rigid";
    r.kept_reason = r.prior ? "the surface-rigid pose lowers the MAP objective against the " + r.prior->source + " prior (" +
                                  std::to_string(r.icp.objective_start) + " -> " + std::to_string(r.icp.objective_result) + ")"
                            : "surface-rigid ICP (" + r.icp.summary.termination + "; no prior to judge it against)";
  }
  if (!rq.rigid_only && rq.nonrigid_method == "loads") {
    const Eigen::Matrix3Xd data_Model = r.X_IntraopModel.inverse() * rq.points_Intraop_mm;
    if (rq.prebuilt_basis && rq.prebuilt_basis->dofs != 3 * scene.problem.mesh.num_vertices())
      throw std::invalid_argument("the prebuilt load basis is for a mesh of " + std::to_string(rq.prebuilt_basis->dofs / 3) +
                                  " vertices, the scene's has " + std::to_string(scene.problem.mesh.num_vertices()));
    const std::shared_ptr<const LoadBasis> built = rq.prebuilt_basis ? nullptr : std::make_shared<const LoadBasis>(build_load_basis(scene, rq.basis));
    const LoadBasis& basis = rq.prebuilt_basis ? *rq.prebuilt_basis : *built;
    LoadFitOptions o = rq.loads;
    o.noise_mm = r.noise_mm;
    if (r.prior && rq.X_IntraopModel_initial && !scene.problem.fixed_vertices.empty() && rq.prior.support_sigma_mm > 0) {
      o.support_sigma_mm = rq.prior.support_sigma_mm;
      r.supports_held = true;
    }
    o.keep_fraction = rq.nonrigid.keep_fraction;
    o.max_distance_mm = rq.nonrigid.max_distance_mm;
    o.min_improvement = rq.nonrigid.min_improvement;
    // The load fit from a rigid start X_start (the data mapped into Model by it); the prior
    // on the total pose is written for the fit's correction D: X' = X_start^-1 * X_prior.
    auto fit_from = [&](const Eigen::Isometry3d& X_start) {
      LoadFitOptions oo = o;
      // A landmark prior is not added when the fit uses the landmarks themselves (its
      // landmark term): they would be counted twice.
      const bool landmarks_in_fit = o.landmark_error_mm > 0 && !rq.landmarks.empty();
      if (r.prior && !(r.prior->source == "landmarks" && landmarks_in_fit)) {
        PosePrior pd = *r.prior;
        pd.X_IntraopModel = X_start.inverse() * r.prior->X_IntraopModel;
        oo.pose_prior = pd;
      }
      std::vector<LandmarkPair> lm;
      for (const auto& l : rq.landmarks) lm.push_back({l.p_Model_mm, X_start.inverse() * l.p_Intraop_mm});
      return fit_load_basis(scene, basis, X_start.inverse() * rq.points_Intraop_mm, lm, oo);
    };
    LoadFitResult fit = fit_from(r.X_IntraopModel);
    // The other rigid candidate: the ICP pose when the start was kept, the prior's mean
    // when the ICP pose was.
    const bool icp_usable = r.icp.summary.iterations > 0 && r.icp.summary.termination != "numerical failure" &&
                            r.icp.summary.termination.rfind("too few inliers", 0) != 0;
    const bool kept_start = r.prior && pose_deviation(*r.prior, r.X_IntraopModel.inverse()).norm() <= 1e-9;
    const Eigen::Isometry3d X_icp = r.icp.X_IntraopModel_fit;
    if (kept_start && icp_usable && pose_deviation(*r.prior, X_icp.inverse()).norm() > 1e-9) {
      const LoadFitResult alt = fit_from(X_icp);
      const double from_start = fit.accepted ? fit.objective_fit : fit.objective_rigid;
      const double from_icp = alt.accepted ? alt.objective_fit : alt.objective_rigid;
      r.notes.push_back("load fit from the " + r.prior->source + " pose: MAP objective " + std::to_string(from_start) + (fit.accepted ? " (fitted)" : " (rigid)") +
                        "; from the surface-rigid pose: " + std::to_string(from_icp) + (alt.accepted ? " (fitted)" : " (rigid)"));
      if (alt.accepted && from_icp < from_start) {
        const double t = fit.wall_time_s;
        fit = alt;
        fit.wall_time_s += t;
        r.X_IntraopModel = X_icp;
        r.kept_stage = "surface_rigid";
        r.kept_reason = "the surface-rigid pose with the load fit from it has a lower MAP objective than the " + r.prior->source + " pose";
      } else {
        fit.wall_time_s += alt.wall_time_s;
      }
    } else if (r.prior && !kept_start) {
      // The surface-rigid pose left the prior's mean: fit also from the mean and keep the
      // candidate (each start, rigid or fitted) with the lowest MAP objective - a pose the
      // partial surface pulled along a local dent is judged against the prior with the
      // deformation that explains the dent.
      const LoadFitResult alt = fit_from(r.prior->X_IntraopModel);
      const double from_rigid = fit.accepted ? fit.objective_fit : fit.objective_rigid;
      const double from_prior = alt.accepted ? alt.objective_fit : alt.objective_rigid;
      r.notes.push_back("load fit from the surface-rigid pose: MAP objective " + std::to_string(from_rigid) + (fit.accepted ? " (fitted)" : " (rigid)") +
                        "; from the " + r.prior->source + " prior's mean: " + std::to_string(from_prior) + (alt.accepted ? " (fitted)" : " (rigid)"));
      if (from_prior < from_rigid) {
        const double t = fit.wall_time_s;
        fit = alt;
        fit.wall_time_s += t;
        r.X_IntraopModel = r.prior->X_IntraopModel;
        r.kept_stage = "start";
        r.kept_reason = "the " + r.prior->source + " pose (with the load fit from it) has a lower MAP objective than the surface-rigid pose";
        r.posterior = alt.posterior.valid ? alt.posterior : pose_posterior(&*r.prior, r.X_IntraopModel.inverse(), r.prior->centre_Model_mm, Matrix6d::Zero(), 1.0);
      } else {
        fit.wall_time_s += alt.wall_time_s;
      }
    }
    r.basis_modes = basis.modes();
    r.basis_time_s = rq.prebuilt_basis ? 0.0 : basis.build_time_s;
    NonrigidResult nr;
    nr.model = "linear elastic load basis (" + std::to_string(basis.patches) + " surface patches x 3, " + std::to_string(basis.gravity) +
               " gravity, " + std::to_string(basis.support) + " support modes" + (basis.supported ? "" : "; no support declared") + ")";
    nr.x_Model_mm = fit.x_Model_mm;
    nr.accepted = fit.accepted;
    nr.message = fit.message;
    nr.rigid_rms_mm = fit.rigid_rms_mm;
    nr.final_rms_mm = fit.final_rms_mm;
    nr.discrepancy_mm = o.noise_mm;
    nr.crossed_vertices = fit.crossed_vertices;
    nr.wall_time_s = r.basis_time_s + fit.wall_time_s;
    for (const LoadFitIteration& it : fit.iterations) {
      NonrigidLevel l;
      l.data_weight = it.lambda;
      l.updates = 1;
      l.elastic_energy = it.strain_energy;
      l.rms_mm = it.rms_mm;
      l.points_used = it.points_used;
      l.points_trimmed = static_cast<int>(data_Model.cols()) - it.points_used;
      l.termination = "predicted " + std::to_string(it.predicted_rms_mm) + " mm";
      nr.levels.push_back(l);
    }
    if (fit.accepted) {
      r.X_IntraopModel = r.X_IntraopModel * fit.D.inverse();
      r.x_Model_mm = fit.x_Model_mm;
      r.deformed = true;
      r.kept_stage = "nonrigid";
      r.kept_reason = "the load fit lowers the surface misfit and the MAP objective (" + std::to_string(fit.objective_rigid) + " -> " +
                      std::to_string(fit.objective_fit) + (r.prior ? ", with the pose prior" : "") + (r.supports_held ? " and held supports" : "") + ")";
      if (fit.posterior.valid) r.posterior = fit.posterior;
    } else {
      r.kept_reason += "; non-rigid not kept: " + fit.message;
    }
    r.notes.push_back("non-rigid (load basis, " + std::to_string(basis.modes()) + " modes, " +
                      (rq.prebuilt_basis ? std::string("prebuilt") : "built in " + std::to_string(basis.build_time_s) + " s") + "): " + fit.message);
    r.nonrigid = nr;
    r.loads = std::move(fit);
  } else if (!rq.rigid_only && rq.nonrigid_method != "energy") {
    throw std::invalid_argument("unknown non-rigid method '" + rq.nonrigid_method + "' (use loads or energy)");
  } else if (!rq.rigid_only) {
    const Eigen::Matrix3Xd data_Model = r.X_IntraopModel.inverse() * rq.points_Intraop_mm;
    std::vector<LandmarkPair> lm;
    for (const auto& l : rq.landmarks) lm.push_back({l.p_Model_mm, r.X_IntraopModel.inverse() * l.p_Intraop_mm});
    NonrigidOptions eo = rq.nonrigid;
    eo.noise_mm = r.noise_mm;
    r.nonrigid = register_nonrigid(scene, data_Model, lm, eo);
    r.notes.push_back("non-rigid: " + r.nonrigid->message);
    if (r.nonrigid->accepted) {
      r.x_Model_mm = r.nonrigid->x_Model_mm;
      r.deformed = true;
      r.kept_stage = "nonrigid";
      r.kept_reason = "the energy method lowered the surface misfit (the pose prior is not used by --method energy)";
    }
    const std::vector<int>& fixed = scene.problem.fixed_vertices;
    if (rq.nonrigid.anchored_boundary && !rq.nonrigid.scene_boundary && r.deformed && fixed.size() >= 3) {
      // The free fit moved the attachment region by (about) a rigid motion T: the rigid
      // part's error. X_IntraopModel * T places the attachment where the free fit put it.
      std::vector<Eigen::Vector3d> moved, rest;
      for (int v : fixed) {
        moved.push_back(r.x_Model_mm.col(v));
        rest.push_back(scene.problem.mesh.rest_positions_World_mm.col(v));
      }
      Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
      bool ok = true;
      try {
        T = calib::register_paired_points(moved, rest).X_AB;
      } catch (const std::exception& e) {
        ok = false;
        r.notes.push_back(std::string("anchored boundary skipped: ") + e.what());
      }
      if (ok) {
        const Eigen::Isometry3d X1 = r.X_IntraopModel * T;
        const Eigen::Matrix3Xd data1 = X1.inverse() * rq.points_Intraop_mm;
        std::vector<LandmarkPair> lm1;
        for (const auto& l : rq.landmarks) lm1.push_back({l.p_Model_mm, X1.inverse() * l.p_Intraop_mm});
        NonrigidOptions o1 = rq.nonrigid;
        o1.scene_boundary = true;
        NonrigidResult second = register_nonrigid(scene, data1, lm1, o1);
        second.wall_time_s += r.nonrigid->wall_time_s;
        const double angle_deg = Eigen::AngleAxisd(T.linear()).angle() * 180.0 / 3.14159265358979323846;
        r.notes.push_back("anchored boundary: rigid part corrected by " + std::to_string(T.translation().norm()) + " mm / " +
                          std::to_string(angle_deg) + " deg (the free fit's motion of the " + std::to_string(fixed.size()) +
                          " fixed vertices); second fit: " + second.message);
        if (second.accepted) {
          r.X_IntraopModel = X1;
          r.x_Model_mm = second.x_Model_mm;
          second.rigid_rms_mm = r.nonrigid->rigid_rms_mm;
          r.nonrigid = second;
        }
      }
    }
  }
  r.wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

Eigen::Matrix3Xd carry_to_intraop(const Scene& scene, const Embedding& embedding, const RegistrationResult& result) {
  return result.X_IntraopModel * embedding.apply(scene.problem.mesh, result.x_Model_mm);
}

}  // namespace arnav::host
