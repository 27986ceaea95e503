#include "host/cut/transection.hpp"

#include <Eigen/LU>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "host/cut/cut_session.hpp"
#include "host/cut/mesh_checks.hpp"

namespace arnav::host::cut {

namespace {

double tet_volume(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, const Eigen::Vector3d& d) {
  return std::abs((b - a).dot((c - a).cross(d - a))) / 6.0;
}

// Volume of the part of tet p[0..3] where the signed distance s (per vertex) is > 0.
double positive_part(const std::array<Eigen::Vector3d, 4>& p, const std::array<double, 4>& s) {
  std::vector<int> in, out;
  for (int i = 0; i < 4; ++i) (s[i] > 0.0 ? in : out).push_back(i);
  const auto cross = [&](int i, int j) -> Eigen::Vector3d { return p[i] + s[i] / (s[i] - s[j]) * (p[j] - p[i]); };
  const double whole = tet_volume(p[0], p[1], p[2], p[3]);
  switch (in.size()) {
    case 0: return 0.0;
    case 4: return whole;
    case 1: {
      const int a = in[0];
      return tet_volume(p[a], cross(a, out[0]), cross(a, out[1]), cross(a, out[2]));
    }
    case 3: {
      const int a = out[0];
      return whole - tet_volume(p[a], cross(a, in[0]), cross(a, in[1]), cross(a, in[2]));
    }
    default: {  // a wedge: triangle (a, a-c, a-d) over (b, b-c, b-d)
      const int a = in[0], b = in[1], c = out[0], d = out[1];
      const Eigen::Vector3d A0 = p[a], A1 = cross(a, c), A2 = cross(a, d), B0 = p[b], B1 = cross(b, c), B2 = cross(b, d);
      return tet_volume(A0, A1, A2, B0) + tet_volume(A1, A2, B0, B1) + tet_volume(A2, B0, B1, B2);
    }
  }
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5))];
}

// Where a point given in the cut mesh's rest coordinates inside cut tet t was at the stroke's
// start: its barycentric weights in the input tet t came from, applied to x0 of that tet.
Eigen::Vector3d material_position(const TetMesh& input, const Eigen::Matrix3Xd& x0, int input_tet, const Eigen::Vector3d& rest) {
  const auto& in = input.tets[static_cast<std::size_t>(input_tet)];
  Eigen::Matrix3d D;
  for (int k = 0; k < 3; ++k) D.col(k) = input.rest_positions_World_mm.col(in[k + 1]) - input.rest_positions_World_mm.col(in[0]);
  const Eigen::Vector3d l = D.partialPivLu().solve(rest - input.rest_positions_World_mm.col(in[0]));
  return (1 - l.sum()) * x0.col(in[0]) + l[0] * x0.col(in[1]) + l[1] * x0.col(in[2]) + l[2] * x0.col(in[3]);
}

// The explicit mass-spring integrator is refused at load when even the step control's budget
// (8x its substeps at 1/60 s) is beyond its stability bound (check_setting_holds): the smallest
// substep count (in 25 % steps) it accepts, +25 % when raised. Within the budget it takes the
// factor its bound needs itself (MassSpringModel::explicit_substeps).
ModelConfig holding_config(const Scene& sc, ModelConfig config) {
  for (int k = 0; k < 40; ++k) {
    try {
      check_setting_holds(sc.problem, config, sc.time_step_s);
      if (k > 0) config.substeps = static_cast<int>(std::ceil(1.25 * config.substeps));
      return config;
    } catch (const std::invalid_argument&) {
      config.substeps = static_cast<int>(std::ceil(1.25 * config.substeps));
    }
  }
  return config;
}

}  // namespace

double clipped_rest_volume_mm3(const TetMesh& mesh, const Eigen::Matrix3Xd& x, const Eigen::Vector3d& n, double d, int side) {
  double total = 0.0;
  for (const auto& tet : mesh.tets) {
    std::array<Eigen::Vector3d, 4> p, r;
    std::array<double, 4> s{};
    for (int k = 0; k < 4; ++k) {
      p[k] = x.col(tet[k]);
      r[k] = mesh.rest_positions_World_mm.col(tet[k]);
      s[k] = side * (n.dot(p[k]) - d);
    }
    const double deformed = tet_volume(p[0], p[1], p[2], p[3]);
    if (!(deformed > 0.0)) continue;
    total += tet_volume(r[0], r[1], r[2], r[3]) * positive_part(p, s) / deformed;
  }
  return total;
}

std::string TransectionResult::summary() const {
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "frames=%d unhealthy=%d refused=%d tets_cut=%d pieces=%d (after the first stroke %d) across=%d sides=%.1f/%.1f mm^3 (expected %.1f/%.1f) "
                "peak_inverted=%d frames_inverted=%d step median=%.2f p99=%.2f ms frame median=%.2f p99=%.2f ms %s",
                frames, unhealthy_steps, refused, tets_cut, pieces, pieces_after_first_stroke, pieces_across_plane, side_volume_mm3[0], side_volume_mm3[1],
                expected_side_volume_mm3[0], expected_side_volume_mm3[1], peak_inverted, frames_with_inverted, median(step_ms),
                percentile(step_ms, 0.99), median(frame_ms), percentile(frame_ms, 0.99), first_unhealthy.substr(0, 240).c_str());
  return buf;
}

TransectionResult run_transection(const Scene& sc, const ModelVariant& variant, const TransectionSettings& settings) {
  ModelConfig config = variant.config;
  config.threads = settings.threads;
  if (config.kind == "mass_spring" && config.integrator == "explicit") config = holding_config(sc, config);
  CutSessionSettings cs;
  cs.min_dihedral_deg = settings.min_dihedral_deg;
  CutSession session(sc.problem, config, cs);
  const TetMesh& input = sc.problem.mesh;
  TransectionResult r;
  r.uncut_volume_mm3 = check_cut_mesh(input).total_volume_mm3;
  const double dt = sc.time_step_s;
  const Eigen::Vector3d n = Eigen::Vector3d::UnitX();
  const double plane = input.rest_positions_World_mm.row(0).mean();
  // The blade: vertical, in the plane, from below the organ to above it; it travels along y.
  const auto blade_at = [&](const Eigen::Matrix3Xd& x, double y) {
    const double z0 = x.row(2).minCoeff() - settings.margin_mm, z1 = x.row(2).maxCoeff() + settings.margin_mm;
    return BladeSegment{Eigen::Vector3d(plane, y, z0), Eigen::Vector3d(plane, y, z1)};
  };
  const auto frame = [&](const BladeSegment& blade, bool cutting) {
    const auto t0 = std::chrono::steady_clock::now();
    const CutFrameReport rep = session.apply_blade(blade, cutting);
    r.tets_cut += rep.cut.tets_cut;
    const StepSummary s = session.step(dt);
    r.frame_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    r.step_ms.push_back(s.wall_time_ms);
    ++r.frames;
    if (s.inverted_elements > 0) ++r.frames_with_inverted;
    r.peak_inverted = std::max(r.peak_inverted, s.inverted_elements);
    if (!s.healthy) {
      if (s.termination == "refused_unstable_dt") ++r.refused;
      if (r.unhealthy_steps++ == 0) r.first_unhealthy = "frame " + std::to_string(r.frames) + ": " + s.warning;
    }
    if (!session.model().positions_World_mm().allFinite()) r.finite = false;
    return s.healthy && r.finite;
  };
  const int settle = static_cast<int>(std::lround(settings.settle_s / dt));
  const int stroke = std::max(1, static_cast<int>(std::lround(settings.stroke_s / dt)));
  const int after = static_cast<int>(std::lround(settings.after_s / dt));
  // Settle with the blade outside the organ (before the near side).
  double y0 = input.rest_positions_World_mm.row(1).minCoeff() - settings.margin_mm;
  for (int f = 0; f < settle; ++f)
    if (!frame(blade_at(session.positions_World_mm(), y0), false)) return r;
  // The stroke: from beyond the near side to beyond the far side of the organ as it is now.
  const Eigen::Matrix3Xd x0 = session.positions_World_mm();
  y0 = x0.row(1).minCoeff() - settings.margin_mm;
  const double y1 = x0.row(1).maxCoeff() + settings.margin_mm;
  r.expected_side_volume_mm3 = {clipped_rest_volume_mm3(input, x0, n, plane, -1), clipped_rest_volume_mm3(input, x0, n, plane, +1)};
  session.apply_blade(blade_at(x0, y0), false);
  for (int f = 1; f <= stroke; ++f)
    if (!frame(blade_at(x0, y0 + (y1 - y0) * f / stroke), true)) return r;
  if (settings.return_stroke) {
    if (!frame(blade_at(x0, y1), false)) return r;  // the first stroke ends (completed)
    r.pieces_after_first_stroke = static_cast<int>(check_cut_mesh(session.mesh()).piece_volume_mm3.size());
    for (int f = 1; f <= stroke; ++f)
      if (!frame(blade_at(x0, y1 + (y0 - y1) * f / stroke), true)) return r;
  }
  const double y_end = settings.return_stroke ? y0 : y1;
  for (int f = 0; f < after; ++f)
    if (!frame(blade_at(x0, y_end), false)) return r;
  // The cut mesh: valid, volume kept, each piece on one side of the plane (where its
  // material was when the stroke began).
  const TetMesh& mesh = session.mesh();
  const CutMeshCheck c = check_cut_mesh(mesh);
  r.mesh_valid = c.valid();
  r.mesh_summary = c.summary();
  r.total_volume_mm3 = c.total_volume_mm3;
  r.pieces = static_cast<int>(c.piece_volume_mm3.size());
  std::vector<std::array<bool, 2>> has(c.piece_volume_mm3.size(), {false, false});
  std::vector<std::array<double, 2>> piece_side(c.piece_volume_mm3.size(), {0.0, 0.0});
  for (int t = 0; t < mesh.num_tets(); ++t) {
    const auto& tet = mesh.tets[static_cast<std::size_t>(t)];
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (int w : tet) centre += 0.25 * mesh.rest_positions_World_mm.col(w);
    const double sd = n.dot(material_position(input, x0, session.cutter().origin_tet(t), centre)) - plane;
    const int piece = c.piece_of_tet[static_cast<std::size_t>(t)];
    std::array<Eigen::Vector3d, 4> p;
    for (int k = 0; k < 4; ++k) p[k] = mesh.rest_positions_World_mm.col(tet[k]);
    piece_side[static_cast<std::size_t>(piece)][sd > 0.0 ? 1 : 0] += tet_volume(p[0], p[1], p[2], p[3]);
    if (std::abs(sd) > 1.0) has[static_cast<std::size_t>(piece)][sd > 0.0 ? 1 : 0] = true;
  }
  for (std::size_t p = 0; p < has.size(); ++p) {
    if (has[p][0] && has[p][1]) ++r.pieces_across_plane;
    r.side_volume_mm3[piece_side[p][1] > piece_side[p][0] ? 1 : 0] += c.piece_volume_mm3[p];
  }
  return r;
}

}  // namespace arnav::host::cut
