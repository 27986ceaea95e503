// Diagnosis harness (temporary): the ring in the running simulation.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <iostream>
#include <map>
#include <set>

#include "host/cut/cut_session.hpp"
#include "host/cut/mesh_checks.hpp"
#include "host/cut/scalpel_path.hpp"
#include "host/scene/scene.hpp"
#include "host/sim/model_factory.hpp"

using namespace arnav::host;
using namespace arnav::host::cut;

namespace {
const std::string kData = std::getenv("ARNAV_DATA_DIR") ? std::getenv("ARNAV_DATA_DIR") : "data";

struct RingGeom {
  double x = 71, y = 156, r = 25, bottom_z = 106;
};

// Faces joining tets inside the ring (vertices not on a cut within r, above bottom) to outside ones.
void holes(const TetMesh& mesh, const Eigen::Matrix3Xd& x, const TetCutter& cutter, const RingGeom& ring, const std::string& what, double zmin) {
  auto cls = [&](int t) {
    int in = 0, out = 0;
    for (int w : mesh.tets[static_cast<std::size_t>(t)]) {
      if (cutter.on_cut(w)) continue;
      const Eigen::Vector3d m = x.col(w);
      (std::hypot(m.x() - ring.x, m.y() - ring.y) < ring.r && m.z() > ring.bottom_z ? in : out) += 1;
    }
    return in > 0 && out == 0 ? 1 : (out > 0 && in == 0 ? 0 : 2);
  };
  std::map<std::array<int, 3>, int> faces;
  int n = 0;
  for (int t = 0; t < mesh.num_tets(); ++t) {
    const auto& q = mesh.tets[static_cast<std::size_t>(t)];
    for (int k = 0; k < 4; ++k) {
      std::array<int, 3> f{q[static_cast<std::size_t>(k)], q[static_cast<std::size_t>((k + 1) % 4)], q[static_cast<std::size_t>((k + 2) % 4)]};
      std::sort(f.begin(), f.end());
      const auto it = faces.find(f);
      if (it == faces.end()) {
        faces[f] = t;
        continue;
      }
      const int a = cls(it->second), b = cls(t);
      if (a < 2 && b < 2 && a != b) {
        Eigen::Vector3d m = Eigen::Vector3d::Zero();
        for (int w : f) m += x.col(w) / 3.0;
        if (m.z() < zmin) continue;
        ++n;
        std::cout << what << " hole: face at r " << std::hypot(m.x() - ring.x, m.y() - ring.y) << " z " << m.z() << " angle "
                  << std::atan2(m.y() - ring.y, m.x() - ring.x) * 180 / M_PI << " tets " << it->second << "/" << t << " (origin " << cutter.origin_tet(it->second)
                  << "/" << cutter.origin_tet(t) << ");";
        for (int tt : {it->second, t})
          for (int w : mesh.tets[static_cast<std::size_t>(tt)]) {
            const Eigen::Vector3d pw = x.col(w);
            std::cout << " " << w << (cutter.on_cut(w) ? "*" : "") << "[s" << cutter.side(w) << "](r " << std::hypot(pw.x() - ring.x, pw.y() - ring.y) << " z " << pw.z()
                      << " a " << std::atan2(pw.y() - ring.y, pw.x() - ring.x) * 180 / M_PI << ")";
          }
        std::cout << "\n";
      }
    }
  }
  std::cout << what << ": " << n << " hole faces\n";
}

// Shortest face path (through faces not separated) from the tumour's tets to a tet clearly outside the block.
void path_out(const TetMesh& mesh, const Eigen::Matrix3Xd& x, const TetCutter& cutter, const RingGeom& ring, const std::vector<int>& start) {
  auto outside = [&](int t) {
    for (int w : mesh.tets[static_cast<std::size_t>(t)]) {
      const Eigen::Vector3d m = x.col(w);
      if (!(std::hypot(m.x() - ring.x, m.y() - ring.y) > ring.r + 4 || m.z() < ring.bottom_z - 4)) return false;
    }
    return true;
  };
  std::map<std::array<int, 3>, std::vector<int>> by_face;
  for (int t = 0; t < mesh.num_tets(); ++t) {
    const auto& q = mesh.tets[static_cast<std::size_t>(t)];
    for (int k = 0; k < 4; ++k) {
      std::array<int, 3> f{q[static_cast<std::size_t>(k)], q[static_cast<std::size_t>((k + 1) % 4)], q[static_cast<std::size_t>((k + 2) % 4)]};
      std::sort(f.begin(), f.end());
      by_face[f].push_back(t);
    }
  }
  std::vector<std::vector<int>> adj(static_cast<std::size_t>(mesh.num_tets()));
  for (const auto& [f, ts] : by_face)
    if (ts.size() == 2) {
      adj[static_cast<std::size_t>(ts[0])].push_back(ts[1]);
      adj[static_cast<std::size_t>(ts[1])].push_back(ts[0]);
    }
  std::vector<int> parent(static_cast<std::size_t>(mesh.num_tets()), -2), queue;
  for (int t : start) {
    parent[static_cast<std::size_t>(t)] = -1;
    queue.push_back(t);
  }
  int found = -1;
  for (std::size_t i = 0; i < queue.size() && found < 0; ++i)
    for (int n : adj[static_cast<std::size_t>(queue[i])]) {
      if (parent[static_cast<std::size_t>(n)] != -2) continue;
      parent[static_cast<std::size_t>(n)] = queue[i];
      if (outside(n)) {
        found = n;
        break;
      }
      queue.push_back(n);
    }
  std::cout << "path out (reached " << queue.size() << " tets):\n";
  for (int t = found; t >= 0; t = parent[static_cast<std::size_t>(t)]) {
    std::cout << "  tet " << t << " (origin " << cutter.origin_tet(t) << "):";
    for (int w : mesh.tets[static_cast<std::size_t>(t)]) {
      const Eigen::Vector3d pw = x.col(w);
      std::cout << " " << w << (cutter.on_cut(w) ? "*" : "") << "[s" << cutter.side(w) << "](r " << std::hypot(pw.x() - ring.x, pw.y() - ring.y) << " z " << pw.z()
                << " a " << std::atan2(pw.y() - ring.y, pw.x() - ring.x) * 180 / M_PI << ")";
    }
    std::cout << "\n";
  }
}

TEST(RingSessionDiag, Run) {
  const char* model_env = std::getenv("RING_MODEL");
  const std::string model = model_env ? model_env : "corotational_fem/implicit";
  const Scene scene = load_scene(kData + "/liver/liver_coarse_cut.scene.yaml");
  ModelConfig config;
  for (const auto& v : model_variants())
    if (v.label.rfind(model, 0) == 0) {
      config = v.config;
      break;
    }
  CutSessionSettings settings;
  settings.cut.snap_fraction = scene.cutting->snap_fraction;
  settings.cut.path_tolerance_mm = scene.cutting->path_tolerance_mm;
  settings.sweep_strips = scene.cutting->sweep_strips;
  auto session = make_cut_session(scene, config, settings);
  const ScalpelPath path = load_scalpel_csv(kData + "/liver/scalpel_ring.csv");
  const int frames = static_cast<int>(path.samples.back().t_s / scene.time_step_s) + 1;
  const bool frozen = std::getenv("RING_FROZEN") != nullptr;
  RingGeom ring;
  bool prev = false;
  int strokes = 0;
  for (int f = 1; f <= frames; ++f) {
    const ScalpelSample s = path.at(f * scene.time_step_s);
    session->apply_blade(s.blade, s.cutting);
    if (!(frozen && strokes > 0 && s.cutting)) {
      const StepSummary st = session->step(scene.time_step_s);
      if (!st.healthy) {
        std::cout << "unhealthy at " << f << ": " << st.warning << "\n";
        break;
      }
    }
    if (s.cutting && !prev) ++strokes;
    if (std::getenv("RING_TRACK") && strokes == (std::getenv("RING_STROKE") ? std::atoi(std::getenv("RING_STROKE")) : 1) && s.cutting) {
      const Eigen::Vector3d b = s.blade.tip_World_mm;
      const double ba = std::atan2(b.y() - ring.y, b.x() - ring.x) * 180 / M_PI;
      const Eigen::Matrix3Xd x = session->positions_World_mm();
      const int a = std::atoi(std::getenv("RING_TRACK")), c = std::atoi(std::getenv("RING_TRACK2"));
      auto pr = [&](int w) {
        const Eigen::Vector3d pw = x.col(w);
        std::cout << " v" << w << (session->cutter().on_cut(w) ? "*" : "") << "[s" << session->cutter().side(w) << "](r " << std::hypot(pw.x() - ring.x, pw.y() - ring.y) << " z " << pw.z()
                  << " a " << std::atan2(pw.y() - ring.y, pw.x() - ring.x) * 180 / M_PI << ")";
      };
      if (session->last_sweep()) {
        const auto tris = session->last_sweep()->triangles();
        for (std::size_t i = 0; i < tris.size(); ++i) {
          double u = 0;
          if (segment_triangle_intersection(x.col(a), x.col(c), tris[i], u)) std::cout << "frame " << f << " sweep crosses the edge at " << u << " tri " << i << "\n";
        }
        if (f == -1) {
          std::cout << "  a " << x.col(a).transpose() << " c " << x.col(c).transpose() << "\n";
          for (const auto& t : tris) std::cout << "  tri " << t.a.transpose() << " | " << t.b.transpose() << " | " << t.c.transpose() << "\n";
        }
        const auto& fp = session->last_sweep()->from_points;
        if (std::abs(ba - std::atan2(x(1, a) - ring.y, x(0, a) - ring.x) * 180 / M_PI) < 5 && !fp.empty()) {
          std::cout << "  from:";
          for (const auto& q : fp) std::cout << " (" << q.transpose() << ")";
          std::cout << "\n  to: " << session->last_sweep()->to.tip_World_mm.transpose() << " / " << session->last_sweep()->to.heel_World_mm.transpose() << "\n";
        }
      }
      static int last_sa = 9, last_sc = 9;
      const bool changed = session->cutter().side(a) != last_sa || session->cutter().side(c) != last_sc;
      last_sa = session->cutter().side(a);
      last_sc = session->cutter().side(c);
      if (changed || std::abs(ba - std::atan2(x(1, a) - ring.y, x(0, a) - ring.x) * 180 / M_PI) < 3) {
        std::cout << "frame " << f << " blade angle " << ba << " r " << std::hypot(b.x() - ring.x, b.y() - ring.y) << " tets " << session->mesh().num_tets();
        pr(a);
        pr(c);
        std::cout << "\n";
      }
    }
    if (!s.cutting && prev) {
      const CutMeshCheck c = check_cut_mesh(session->mesh());
      std::cout << "stroke " << strokes << " ended frame " << f << ": pieces " << c.piece_volume_mm3.size() << "\n";
      {
        const TetMesh& mesh = session->mesh();
        const Eigen::Matrix3Xd x = session->positions_World_mm();
        const TetCutter& cutter = session->cutter();
        int straddling = 0;
        for (int t = 0; t < mesh.num_tets(); ++t) {
          int in = 0, out = 0;
          for (int w : mesh.tets[static_cast<std::size_t>(t)]) {
            if (cutter.on_cut(w)) continue;
            const Eigen::Vector3d m = x.col(w);
            if (m.z() < 112) continue;
            const double r = std::hypot(m.x() - ring.x, m.y() - ring.y);
            in += r < ring.r - 1;
            out += r > ring.r + 1;
          }
          if (in && out && strokes == 1) {
            ++straddling;
            std::cout << "straddling tet " << t << " (origin " << cutter.origin_tet(t) << "):";
            for (int w : mesh.tets[static_cast<std::size_t>(t)]) {
              const Eigen::Vector3d pw = x.col(w);
              std::cout << " " << w << (cutter.on_cut(w) ? "*" : "") << "[s" << cutter.side(w) << "](r " << std::hypot(pw.x() - ring.x, pw.y() - ring.y) << " z " << pw.z()
                        << " a " << std::atan2(pw.y() - ring.y, pw.x() - ring.x) * 180 / M_PI << ")";
            }
            std::cout << "\n";
          }
        }
        if (const char* list = std::getenv("RING_TETS")) {
          std::string l = list;
          std::size_t pos = 0;
          while (pos < l.size()) {
            const std::size_t comma = l.find(',', pos);
            const int t = std::atoi(l.substr(pos, comma - pos).c_str());
            pos = comma == std::string::npos ? l.size() : comma + 1;
            if (t >= mesh.num_tets()) continue;
            std::cout << "tet " << t << " (origin " << cutter.origin_tet(t) << "):";
            for (int w : mesh.tets[static_cast<std::size_t>(t)]) {
              const Eigen::Vector3d pw = x.col(w);
              std::cout << " " << w << (cutter.on_cut(w) ? "*" : "") << "[s" << cutter.side(w) << "](r " << std::hypot(pw.x() - ring.x, pw.y() - ring.y) << " z " << pw.z()
                        << " a " << std::atan2(pw.y() - ring.y, pw.x() - ring.x) * 180 / M_PI << ")";
            }
            std::cout << "\n";
          }
        }
        std::cout << "straddling " << straddling << "\n" << cutter.describe_pending() << "\n";
      }
      holes(session->mesh(), session->positions_World_mm(), session->cutter(), ring, "stroke" + std::to_string(strokes), strokes == 1 ? 112 : 0);
    }
    prev = s.cutting;
  }
  const CutMeshCheck c = check_cut_mesh(session->mesh());
  {
    std::vector<int> start;
    for (int t : session->tumours().front().embedding.tet) start.push_back(t);
    path_out(session->mesh(), session->positions_World_mm(), session->cutter(), ring, start);
  }
  std::cout << "end: pieces " << c.piece_volume_mm3.size() << " valid " << c.valid() << "\n";
  for (double v : c.piece_volume_mm3) std::cout << " piece " << v << "\n";
}

}  // namespace
