// scripts/demo's AR session end to end (hil_tests/scenarios/ar_session.sh, ~2 min with the
// phantom's recording): the synthetic camera films the deforming phantom (a grasper pulls
// the organ's underside from when the scalpel comes in), the simulated Polaris moves the
// pointer over four landmarks and the scalpel round a ring about the tumour on paths
// scripted in the model frame (make_demo_paths.py from the scene) and the grasper on the
// phantom's recorded path; arnav-can-sim presses the pedal's accept switch at each dwell and
// holds the cut pedal through the ring, through the can_shim and arnav-appliance's CAN path;
// all on the bench's world clock; the camera is unplugged for 1 s between registration and
// cut. Checked from the run's files: live registration complete with a small FRE and
// X_RefModel near the bench's truth, the grasper coupled to the cutting model through the
// pull, a cut made (cut faces in overlay.csv only while the pedal was held, cut-path error
// in the material), the AR error against the deformed ground truth clearly below an
// overlay that ignores the deformation, the camera fault and its recovery, the CSV complete.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <regex>
#include <cstdint>
#include <sstream>
#include <thread>
#include <vector>

#include <unistd.h>

#include <nlohmann/json.hpp>

#include "calibration/lib/point_registration.hpp"
#include "calibration/lib/rigid_transform_file.hpp"
#include "hil_tests/bench/bench_required.hpp"

namespace arnav::hil {
namespace {

// name,x_mm,y_mm,z_mm[,...] rows after a header ('#' lines skipped).
std::vector<Eigen::Vector3d> read_points_csv(const std::filesystem::path& path) {
  std::ifstream in(path);
  EXPECT_TRUE(in.good()) << path;
  std::vector<Eigen::Vector3d> out;
  std::string line;
  bool header = true;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    if (header) {
      header = false;
      continue;
    }
    std::stringstream ss(line);
    std::string name, x, y, z;
    std::getline(ss, name, ',');
    std::getline(ss, x, ',');
    std::getline(ss, y, ',');
    std::getline(ss, z, ',');
    out.emplace_back(std::stod(x), std::stod(y), std::stod(z));
  }
  return out;
}

std::string env(const char* name, const char* fallback) {
  const char* v = std::getenv(name);
  return v ? v : fallback;
}

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> cells;
  std::stringstream s(line);
  std::string c;
  while (std::getline(s, c, ',')) cells.push_back(c);
  if (!line.empty() && line.back() == ',') cells.emplace_back();
  return cells;
}

struct CutVertexRow {
  int id = 0;
  double values[6] = {};
};

std::vector<CutVertexRow> read_cut_vertices(const std::filesystem::path& path) {
  std::vector<CutVertexRow> rows;
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    const auto cells = split(line);
    if (cells.size() != 7) {
      ADD_FAILURE() << path << ": " << line;
      break;
    }
    CutVertexRow r;
    r.id = std::stoi(cells[0]);
    for (int k = 0; k < 6; ++k) r.values[k] = std::stod(cells[static_cast<std::size_t>(k + 1)]);
    rows.push_back(r);
  }
  return rows;
}

// The cut-path error in the material (docs/overlay.md): the per-step worst new cut vertex
// against the surfaces the blade swept, live and replayed. Live, it came from a model thread
// that fell seconds behind beside busy processes and skipped model time in the middle of the
// stroke; the stroke's steps are never skipped and a cutting session runs the model above
// the machine's other work (docs/overlay.md, "Model clock", "Threads and cores"). The
// cutter's own tail (chords' mid-points on the coarse mesh, edges 16-40 mm against the
// ring's 21 mm radius) is removed by refining the tets ahead of the blade where the cut
// curves (the demo scene's chord_sagitta_mm 3; docs/cut.md). Issue 20's targets, held live
// and replayed: p95 <= 1.0, max <= 3.0 mm (five logs with the code of the eleventh session:
// max 0.80-2.80 mm; docs/benchmarks.md).
void print_cut_path(const nlohmann::json& cutting, const char* run) {
  std::cerr << "[ar demo] " << run << " cut-path error in the material: p50 " << cutting["path_error_mm"]["p50"].get<double>() << ", p95 "
            << cutting["path_error_mm"]["p95"].get<double>() << ", max " << cutting["path_error_mm"]["max"].get<double>() << " mm over "
            << cutting["steps_with_new_cut_vertices"].get<int>() << " steps\n";
}

void expect_cut_on_the_blades_path(const nlohmann::json& cutting, const char* run) {
  EXPECT_GT(cutting["cut_faces"].get<int>(), 20) << run << ": " << cutting.dump();
  EXPECT_LT(cutting["path_error_mm"]["p50"].get<double>(), 0.5) << run << ": " << cutting.dump();
  EXPECT_LE(cutting["path_error_mm"]["p95"].get<double>(), 1.0) << run << ": " << cutting.dump();
  EXPECT_LE(cutting["path_error_mm"]["max"].get<double>(), 3.0) << run << ": " << cutting.dump();
  print_cut_path(cutting, run);
}

TEST(ArDemoSession, LiveRegistrationRingCutFaultAndRecording) {
  ARNAV_BENCH_OR_SKIP(::geteuid() != 0 ? "needs root for a private network namespace (unshare --net)" : "");
  const std::filesystem::path out = std::filesystem::temp_directory_path() / ("arnav-ar-demo-" + std::to_string(::getpid()));
  std::filesystem::remove_all(out);
  const std::string src = env("ARNAV_SOURCE_DIR", ".");
  const std::string build = env("ARNAV_BINARY_DIR", ".");
  // The session runs with one spinning process per core beside it (ar_session.sh,
  // ARNAV_SESSION_HOGS; issue 20): the cut must land where the blade went with every core
  // busy, not only on an idle machine. The phantom's recording before it and the replays after
  // it run without them (the busy replay below has its own).
  const std::string hogs = std::to_string(std::max(1u, std::thread::hardware_concurrency()));
  const std::string cmd = "ARNAV_SESSION_HOGS=" + hogs + " " + src + "/hil_tests/scenarios/ar_session.sh " + build + " " + out.string() + " >" +
                          (out.string() + ".log") + " 2>&1";
  const int rc = std::system(cmd.c_str());
  std::ifstream log_in(out.string() + ".log");
  std::stringstream log;
  log << log_in.rdbuf();
  ASSERT_EQ(rc, 0) << log.str();
  EXPECT_NE(log.str().find("registration FRE/TRE: FRE"), std::string::npos) << log.str();
  EXPECT_NE(log.str().find("cut-path error p50"), std::string::npos) << log.str();
  // Sealed, under attack all session long (ar_bench.sh ar_start_attacker): the host's count, none accepted.
  EXPECT_TRUE(std::regex_search(log.str(), std::regex(R"(security: [1-9][0-9]* injected \(forged [1-9][0-9]*/replayed [1-9][0-9]*/tampered [1-9][0-9]*.*\), 0 accepted)")))
      << log.str();

  std::ifstream host_in(out / "host.json");
  const nlohmann::json nav = nlohmann::json::parse(host_in)["navigation"];

  // Live registration: every landmark taken, none refused, the registration the touched
  // points give found. The sensors are realistic (docs/hil.md "Sensor errors"): the pointer
  // touches each landmark 2-4 mm off the anatomical point (landmark_touches.csv, seeded) and
  // the simulated Polaris adds 0.25 mm RMS per marker. The FRE and X_RefModel are then not
  // those of the exact points (FRE 0.08 mm before, checked < 1.0 mm; over seeds 1-20 the
  // touches alone give FRE 1.56-2.99 mm, TRE at the tumour centroid 0.62-2.43 mm, mean 1.47,
  // docs/benchmarks.md "Sensor errors"): the expected result is the rigid fit of the touched
  // points to the landmarks (X_true * fit, its RMS residual), computed here from the run's
  // own files; the host must find it to within the old tolerances (1.5 mm, 0.01 rad; FRE
  // within 0.5 mm: Polaris noise and the 0.1 mm tremor).
  const nlohmann::json& r = nav["registration"];
  ASSERT_EQ(r["method"], "live landmarks") << r.dump();
  ASSERT_TRUE(r["done"].get<bool>()) << r.dump() << log.str();
  EXPECT_EQ(r["landmarks_taken"].get<int>(), 4);
  EXPECT_EQ(r["refused"].get<int>(), 0);
  const auto landmarks = read_points_csv(out / "landmarks.csv"), touches = read_points_csv(out / "landmark_touches.csv");
  ASSERT_EQ(landmarks.size(), 4u);
  ASSERT_EQ(touches.size(), 4u);
  const calib::PointRegistrationResult touched = calib::register_paired_points(touches, landmarks);  // touch = fit * landmark
  EXPECT_NEAR(r["fre_mm"].get<double>(), touched.fre_rms_mm, 0.5);
  Eigen::Matrix4d M;
  for (int i = 0; i < 16; ++i) M(i / 4, i % 4) = r["X_RefModel"][static_cast<std::size_t>(i)].get<double>();
  const Eigen::Isometry3d X_true = calib::read_transform(src + "/hil_tests/scenarios/ar_demo/X_RefModel_phantom.yaml").X_ParentChild;
  const Eigen::Isometry3d X_expected = X_true * touched.X_AB;
  EXPECT_LT((M.topRightCorner<3, 1>() - X_expected.translation()).norm(), 1.5) << M;
  EXPECT_LT(Eigen::AngleAxisd(M.topLeftCorner<3, 3>().transpose() * X_expected.linear()).angle(), 0.01) << M;
  // What the touches cost at the tumour: the AR bounds below grow by it (triangle inequality).
  const Eigen::Vector3d c_Model(70, 160, 140);  // the scene's tumour centre (liver_coarse_cut.scene.yaml)
  const double touch_tre_mm = (touched.X_AB * c_Model - c_Model).norm();
  std::cerr << "[ar demo] touches: FRE " << touched.fre_rms_mm << " mm expected, host " << r["fre_mm"].get<double>() << " mm; TRE at the tumour from the touches "
            << touch_tre_mm << " mm\n";

  // The cut: made while the pedal was held, faces present, along the scalpel's path.
  const nlohmann::json& c = nav["cutting"];
  EXPECT_EQ(c["mode"], "input");
  EXPECT_GT(c["frames_cutting"].get<int>(), 30) << c.dump();
  EXPECT_GT(c["cut_faces"].get<int>(), 20) << c.dump();
  EXPECT_GT(c["cut_area_mm2"].get<double>(), 200.0) << c.dump();

  // The grasper: coupled to the cutting model once registered, held through the pull.
  const nlohmann::json& g = nav["grasper"];
  EXPECT_GE(g["grasps"].get<int>(), 1) << g.dump();
  EXPECT_GT(g["max_tip_travel_mm"].get<double>(), 15.0) << g.dump();
  EXPECT_GT(g["steps_grasping"].get<int>(), 300) << g.dump();

  // AR error against the deformed ground truth (the bench's true registration, the phantom's
  // tumour of each frame): the organ moved. Live, on this machine's load, it is printed; the
  // targets are checked on the replay of the session's own log (ar_session.sh: the same
  // frames, poses and pedal, the host's clock the log's; one thread, so a starved rendering
  // or model thread cannot spoil it). The replay steps the model by the log's clock before
  // each message (host/app/main.cpp), so a gap in the grasper's poses in the log (the
  // loaded bench's appliance or LCM) releases the grasp as stale as it did live; the model
  // then misses part of the pull until it grasps again: the p95 target holds only for a
  // replay whose grasp was never released stale (the mean and the comparison with an
  // overlay ignoring the deformation always).
  std::ifstream ar_in(out / "ar_error.json");
  const nlohmann::json ar = nlohmann::json::parse(ar_in);
  EXPECT_GE(ar["frames_evaluated"].get<int>(), 50) << ar.dump();
  ASSERT_TRUE(ar.contains("rigid_overlay")) << "the ground truth is not the deforming phantom's: " << ar.dump();
  const double displacement = ar["tumour_displacement_mm"]["max"].get<double>();
  EXPECT_GT(displacement, 5.0) << ar.dump();
  std::ifstream replay_in(out / "ar_error_replay.json");
  ASSERT_TRUE(replay_in.good()) << log.str();
  const nlohmann::json rep = nlohmann::json::parse(replay_in);
  EXPECT_GE(rep["frames_evaluated"].get<int>(), 50) << rep.dump();
  // The bounds of the exact sensors (1.0 mm mean, 2.0 mm p95) plus the registration error the
  // landmark touches put at the tumour (touch_tre_mm, above): the drawn tumour's error is at
  // most the model's plus the registration's.
  EXPECT_LE(rep["ar_error_mm"]["mean"].get<double>(), 1.0 + touch_tre_mm) << rep.dump();
  std::ifstream replay_host_in(out / "replay.json");
  const nlohmann::json replay_nav = nlohmann::json::parse(replay_host_in)["navigation"];
  const int replay_stale_releases = replay_nav["grasper"]["stale_releases"].get<int>();
  if (replay_stale_releases == 0) {
    EXPECT_LE(rep["ar_error_mm"]["p95"].get<double>(), 2.0 + touch_tre_mm) << rep.dump();
  } else {
    std::cerr << "[ar demo] the replay's grasp was released stale " << replay_stale_releases << " time(s) (gaps in the log's grasper poses): AR error p95 "
              << rep["ar_error_mm"]["p95"].get<double>() << " mm, not held to 2 mm\n";
  }
  // The rigid overlay goes through the true registration, the host's through the touched one.
  EXPECT_LT(rep["ar_error_mm"]["mean"].get<double>(), 0.5 * rep["rigid_overlay"]["ar_error_mm"]["mean"].get<double>() + touch_tre_mm)
      << rep.dump();
  // The honest figures (3-D, availability) are printed, not held yet: measured on too few
  // seeds on this loaded machine (docs/benchmarks.md "Sensor errors").
  for (const auto* which : {&ar, &rep})
    if (which->contains("ar_error_3d_mm"))
      std::cerr << "[ar demo] " << (which == &ar ? "live" : "replay") << ": AR error 3-D mean " << (*which)["ar_error_3d_mm"]["mean"].get<double>()
                << " mm, p95 " << (*which)["ar_error_3d_mm"]["p95"].get<double>() << " mm; availability "
                << (*which)["availability"]["percent"].get<double>() << " %\n";
  // The cut, measured in the material (docs/overlay.md): the tissue's motion after the cut
  // (the grasper's pull, the ring's plug) is not path error; a cut put where the blade was
  // not is. Live and replayed, both with every core busy (issue 20: the tail reached 11 /
  // 23.7 mm in a replay under load when the model took the blade at camera frames and
  // stepped on the host's clock).
  expect_cut_on_the_blades_path(replay_nav["cutting"], "replay");
  // Live, with every core busy: the model thread (nice -5 in a cutting session) keeps up with
  // the blade, and when it falls behind it does not skip model time in a stroke (at nice 5 it
  // fell 5 s behind and merged the stroke's samples: p95 4.5, and up to 5.9 / max 8.5 mm; at
  // nice 0 with the refined cut it fell 5 s behind too; at -5 about 1 s).
  expect_cut_on_the_blades_path(nav["cutting"], "live");
  EXPECT_EQ(nav["model"]["nice"].get<int>(), -5) << nav["model"].dump();
  EXPECT_FALSE(nav["model"].contains("nice_error")) << nav["model"].dump();
  EXPECT_EQ(nav["model"]["clock"]["cut_samples_merged"].get<int>(), 0) << nav["model"].dump();
  // The model steps on the tracker's clock (docs/overlay.md, "Model clock"): the same log
  // replayed again with every core kept busy (one spinning process per core beside it) gives
  // the same cut, vertex for vertex.
  const std::string replay_busy = "bash -c 'hogs=(); for c in $(seq $(nproc)); do (while :; do :; done) & hogs+=($!); done; " + build +
                                  "/host/app/arnav-host " + (out / "session.yaml").string() + " --replay " + (out / "session.lcmlog").string() +
                                  " --replay-speed 0 --quiet --record " + (out / "replay_busy").string() + " >" + (out / "replay_busy.log").string() +
                                  " 2>&1; rc=$?; kill ${hogs[@]}; exit $rc'";
  ASSERT_EQ(std::system(replay_busy.c_str()), 0) << replay_busy;
  const auto cut_first = read_cut_vertices(out / "replay" / "cut_vertices.csv");
  const auto cut_busy = read_cut_vertices(out / "replay_busy" / "cut_vertices.csv");
  ASSERT_GT(cut_first.size(), 20u);
  ASSERT_EQ(cut_busy.size(), cut_first.size());
  double worst_mm = 0.0;
  for (std::size_t i = 0; i < cut_busy.size(); ++i) {
    ASSERT_EQ(cut_busy[i].id, cut_first[i].id);
    for (int k = 0; k < 6; ++k) worst_mm = std::max(worst_mm, std::abs(cut_busy[i].values[k] - cut_first[i].values[k]));
  }
  EXPECT_LE(worst_mm, 1e-6) << "the replay's cut depends on the machine's load";
  EXPECT_EQ(ar["invisible_with_overlay"].get<int>(), 0) << ar.dump();
  // The CSV holds every frame the camera made that the host displayed (the host may drop a
  // few under load; its own count says how many).
  EXPECT_EQ(ar["csv_rows"].get<int>() + ar["missing_in_csv"].get<int>(), ar["truth_frames"].get<int>());
  EXPECT_LE(ar["missing_in_csv"].get<int>(), nav["frames_dropped"].get<int>());

  // overlay.csv (live and replayed): complete rows; cut faces appear only after cutting
  // started, never shrink. Where the cut grew, the blade was on the ring: checked on the
  // replay, whose frames carry the cut of their own scalpel pose (live, on a loaded machine,
  // a late frame can show cut faces the model made from poses the frames in between carried).
  struct CsvCounts {
    int rows = 0, gap_rows = 0, unregistered = 0, last_faces = 0, growth_rows = 0, on_ring_rows = 0;
    bool ring_reached = false;
  };
  const auto read_csv = [&](const std::filesystem::path& path, bool check_ring) {
    CsvCounts n;
    std::ifstream csv(path);
    std::string line;
    EXPECT_TRUE(std::getline(csv, line)) << path;
    const std::vector<std::string> header = split(line);
    const auto col = [&](const char* name) {
      for (std::size_t i = 0; i < header.size(); ++i)
        if (header[i] == name) return static_cast<int>(i);
      ADD_FAILURE() << path << ": no column " << name;
      return 0;
    };
    const int i_cutting = col("cutting"), i_faces = col("cut_faces"), i_flags = col("flags"), i_margin = col("blade_to_margin_mm");
    bool cut_seen = false;
    while (std::getline(csv, line)) {
      const auto cells = split(line);
      if (cells.size() != header.size()) {
        ADD_FAILURE() << path << ": " << line;
        break;
      }
      ++n.rows;
      const int faces = cells[static_cast<std::size_t>(i_faces)].empty() ? 0 : std::stoi(cells[static_cast<std::size_t>(i_faces)]);
      cut_seen = cut_seen || cells[static_cast<std::size_t>(i_cutting)] == "1";
      if (faces > 0) {
        EXPECT_TRUE(cut_seen) << "cut faces before any cutting frame: " << line;
      }
      EXPECT_GE(faces, n.last_faces) << line;
      // The ring's radius is the tumour's largest radius + 5 mm margin + 3 mm clearance, so
      // the blade-to-margin distance is about 3 mm where the ellipsoid is widest and more
      // elsewhere (radii 13, 11, 10), give or take how far the grasper has moved the tumour
      // (the ring is scripted at rest). During the entry (the blade drawn in over a quarter
      // ring from above the surface) the pull brings the tissue onto the blade early: there
      // the cut starts with the blade farther out, by how far depends on when the grasper's
      // pull and the blade's script meet (a loaded run first cut at 40.5 mm, after a 266 ms
      // camera gap), so only from the first growth on the ring is the blade held within 40 mm.
      if (faces > n.last_faces && !cells[static_cast<std::size_t>(i_margin)].empty()) {
        ++n.growth_rows;
        const double d = std::stod(cells[static_cast<std::size_t>(i_margin)]);
        const bool on_ring = d < 9.0 + displacement;
        n.ring_reached = n.ring_reached || on_ring;
        if (check_ring) {
          EXPECT_GT(d, 1.0 - displacement) << line;
          if (n.ring_reached) {
            EXPECT_LT(d, 40.0) << line;
          }
        }
        n.on_ring_rows += on_ring ? 1 : 0;
      }
      n.last_faces = faces;
      n.gap_rows += cells[static_cast<std::size_t>(i_flags)].find("camera_gap") != std::string::npos;
      n.unregistered += cells[static_cast<std::size_t>(i_flags)].find("unregistered") != std::string::npos;
    }
    return n;
  };
  const CsvCounts live = read_csv(out / "recording" / "overlay.csv", false);
  EXPECT_EQ(live.rows, ar["csv_rows"].get<int>());
  EXPECT_GT(live.last_faces, 20);
  EXPECT_GT(live.unregistered, 0) << "frames before the registration carry 'unregistered'";
  EXPECT_GT(live.gap_rows, 0);
  const CsvCounts replayed = read_csv(out / "replay" / "overlay.csv", true);
  EXPECT_EQ(replayed.rows, rep["csv_rows"].get<int>());
  EXPECT_GT(replayed.last_faces, 20);
  EXPECT_GE(replayed.growth_rows, 3) << "the cut should grow over several frames along the ring";
  EXPECT_GE(2 * replayed.on_ring_rows, replayed.growth_rows) << "most of the cut grew with the blade on the ring";

  // The injected fault: the camera unplugged for 1 s and recovered; the host saw the gap.
  std::ifstream app_in(out / "appliance.log");
  std::stringstream app;
  app << app_in.rdbuf();
  EXPECT_NE(app.str().find("CAMERA_LOST"), std::string::npos) << app.str();
  EXPECT_NE(app.str().find("CAMERA_RECOVERED"), std::string::npos) << app.str();
  EXPECT_GE(nav["camera_gaps"]["max_ms"].get<double>(), 900.0);
  EXPECT_TRUE(std::filesystem::file_size(out / "recording" / "overlay.avi") > 0);
  EXPECT_TRUE(std::filesystem::file_size(out / "recording" / "contact_sheet.png") > 0);
  if (!std::getenv("ARNAV_KEEP")) {
    std::filesystem::remove_all(out);
    std::filesystem::remove(out.string() + ".log");
  }
}

}  // namespace
}  // namespace arnav::hil
