// The host's deforming surfaces in an OpenIGTLink client (docs/igtl.md "POLYDATA"): the real
// arnav-host (the AR demo's liver, mass-spring model, gravity on, registration from a
// file, surfaces.publish_rate_hz 10) -> surface_mesh_t on the sealed bus (LCM udpm in the bench's private network
// namespace, a fresh key for both programs) -> the real arnav-igtl -> a client on
// 127.0.0.1 that greets like 3D Slicer. On the bus the surfaces are sealed (a plain LCM
// subscriber cannot decode them). No appliance: the model
// steps on the host clock without tool inputs. Checked: Organ and Tumour POLYDATA with good
// CRCs, UTC time stamps in order, the organ's vertices where the scene's organ is in Ref
// (the registration applied) and moving (sagging), GET_POLYDATA answered from the latest
// mesh again and again, an empty POLYDATA for Cut (no cut in this scene), and both
// programs ending cleanly with their counters.
#include <gtest/gtest.h>

#include <signal.h>

#include <algorithm>
#include <atomic>
#include <set>
#include <thread>

#include <lcm/lcm-cpp.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <nlohmann/json.hpp>

#include "hil_tests/bench/bench_required.hpp"
#include "hil_tests/bench/namespaces.hpp"
#include "hil_tests/scenarios/surface_pipeline.hpp"
#include "host/igtl/messages.hpp"
#include "host/igtl/test/test_client.hpp"
#include "host/scene/scene.hpp"
#include "protocol/clock.hpp"
#include "protocol/testing/child_process.hpp"

namespace arnav::hil {
namespace {

// What a plain LCM subscriber without the key sees on ARNAV_SURFACE_*.
struct RawSurfaces {
  std::atomic<int> messages{0}, decodable{0};
  void on(const lcm::ReceiveBuffer* rb, const std::string&) {
    ++messages;
    surface_mesh_t m;
    if (m.decode(rb->data, 0, static_cast<int>(rb->data_size)) >= 0) ++decodable;
  }
};

// What a client received, as a picture (docs/igtl.md): the meshes seen along Reference's -z
// axis, flat-shaded with a headlight, each back to front and each later mesh on top (the
// tumour inside the organ shown through it, as the overlay does); no Slicer here, for the docs only.
void save_picture(const std::string& path, const std::vector<std::pair<igtl::test::Unpacked, cv::Scalar>>& meshes) {
  Eigen::AlignedBox3d box;
  for (const auto& [u, colour] : meshes)
    for (const auto& p : u.points_mm) box.extend(Eigen::Vector3d(p[0], p[1], p[2]));
  const int size = 640;
  const double scale = 0.9 * size / std::max(box.sizes().x(), box.sizes().y());
  const Eigen::Vector3d centre = box.center();
  struct Face {
    double depth;
    std::vector<cv::Point> px;
    cv::Scalar colour;
  };
  cv::Mat image(size, size, CV_8UC3, cv::Scalar(40, 40, 40));
  for (const auto& [u, colour] : meshes) {
    std::vector<Face> faces;
    for (const auto& poly : u.polygons) {
      if (poly.size() != 3) continue;
      Eigen::Vector3d v[3];
      for (int k = 0; k < 3; ++k) {
        const auto& p = u.points_mm[poly[static_cast<std::size_t>(k)]];
        v[k] = Eigen::Vector3d(p[0], p[1], p[2]);
      }
      const Eigen::Vector3d n = (v[1] - v[0]).cross(v[2] - v[0]).normalized();
      const double light = 0.25 + 0.75 * std::abs(n.z());
      Face f{(v[0].z() + v[1].z() + v[2].z()) / 3.0, {}, colour * light};
      for (const auto& x : v) f.px.emplace_back(static_cast<int>(size / 2 + scale * (x.x() - centre.x())), static_cast<int>(size / 2 - scale * (x.y() - centre.y())));
      faces.push_back(std::move(f));
    }
    std::sort(faces.begin(), faces.end(), [](const Face& a, const Face& b) { return a.depth > b.depth; });  // far (high z) first: seen from -z
    for (const auto& f : faces) cv::fillConvexPoly(image, f.px, f.colour, cv::LINE_AA);
  }
  cv::imwrite(path, image);
}

TEST(HilIgtlPolydata, HostSurfacesReachTheClientInReference) {
  ARNAV_BENCH_OR_SKIP(enter_bench_namespaces());
  // The demo's mass-spring liver (a few ms per step): the organ changes shape between
  // rounds even on a loaded machine (the coarse FEM liver took > 1 s for a step there).
  const std::string scene_path = arnav::testing::source_dir() + "/hil_tests/scenarios/ar_demo/liver_navigation.scene.yaml";
  SurfacePipelineOptions o;
  o.host_exe = ARNAV_HOST_EXE;
  o.igtl_exe = ARNAV_IGTL_EXE;
  o.scene_path = scene_path;
  SurfacePipeline p;
  const std::int64_t t0_wall = wall_us();
  const std::string why = p.start(make_temp_dir("igtl_polydata"), o);
  ASSERT_EQ(why, "");

  RawSurfaces raw;
  std::atomic<bool> raw_stop{false};
  std::thread raw_thread([&] {
    lcm::LCM bus(std::string(SurfacePipeline::kLcmUrl) + "&recv_buf_size=4194304");
    bus.subscribe("ARNAV_SURFACE_.*", &RawSurfaces::on, &raw);
    while (!raw_stop.load()) bus.handleTimeout(50);
  });

  igtl::test::TestClient client(p.port);
  ASSERT_TRUE(client.connected()) << client.why();
  ASSERT_TRUE(client.send(igtl::test::slicer_v2_status()));
  std::vector<igtl::Message> organs, tumours;
  std::set<std::uint64_t> bodies;  // CRCs: different shapes
  for (int i = 0; i < 400 && (organs.size() < 10 || bodies.size() < 2) && !client.closed_by_server(); ++i) {  // up to 40 s
    client.receive_until(1u << 20, 0.1);
    for (auto& m : client.take()) {
      if (m.header.type != "POLYDATA") continue;
      if (m.header.device_name == "Organ") {
        bodies.insert(m.header.crc);
        organs.push_back(std::move(m));
      } else if (m.header.device_name == "Tumour") {
        tumours.push_back(std::move(m));
      }
    }
  }
  ASSERT_GE(organs.size(), 10u) << p.igtl->log_tail() << p.host->log_tail();
  EXPECT_GE(tumours.size(), 1u);
  // Asked for, again and again: answered from the latest mesh; a surface this scene does not have: empty.
  std::size_t answered = 0, empty_cut = 0;
  for (int k = 0; k < 3; ++k) {
    ASSERT_TRUE(client.send(igtl::test::named_request("GET_POLYDATA", "Organ", k == 1 ? 2 : 1)));
    ASSERT_TRUE(client.send(igtl::test::named_request("GET_POLYDATA", "Cut")));
    for (int i = 0; i < 100 && !client.closed_by_server(); ++i) {
      client.receive_until(1u << 20, 0.05);
      bool got_cut = false;
      for (const auto& m : client.take()) {
        if (m.header.type == "POLYDATA" && m.header.device_name == "Cut") {
          got_cut = true;
          empty_cut += m.header.body_size == 0 ? 1 : 0;
        }
        if (m.header.type == "POLYDATA" && m.header.device_name == "Organ") ++answered;
      }
      if (got_cut) break;
    }
  }
  EXPECT_EQ(empty_cut, 3u);
  EXPECT_GE(answered, 3u);  // the answers (and whatever the 10 Hz stream sent meanwhile)
  const std::int64_t t_end_wall = wall_us();
  raw_stop = true;
  raw_thread.join();
  EXPECT_GE(raw.messages.load(), 10) << "no ARNAV_SURFACE_* on the bus";
  EXPECT_EQ(raw.decodable.load(), 0) << "surfaces on the bus without the seal";
  EXPECT_EQ(p.igtl->stop(SIGTERM, 15.0), 0) << p.igtl->log_tail();
  EXPECT_EQ(p.host->stop(SIGTERM, 30.0), 0) << p.host->log_tail();

  // Where the scene's organ is, in Ref: vertex for vertex (the used vertices of its surface, in order of first use).
  const host::Scene scene = host::load_scene(scene_path);
  const Eigen::Isometry3d X_RefModel = surface_pipeline_X_RefModel();
  std::vector<int> order;
  {
    std::vector<bool> seen(static_cast<std::size_t>(scene.organ_surface.positions_World_mm.cols()), false);
    for (const auto& t : scene.organ_surface.tris)
      for (int v : t)
        if (!seen[static_cast<std::size_t>(v)]) {
          seen[static_cast<std::size_t>(v)] = true;
          order.push_back(v);
        }
  }
  std::set<std::vector<float>> geometries;
  std::int64_t last_time = 0;
  double worst_mm = 0.0;
  for (const auto& m : organs) {
    const auto u = igtl::test::unpack(m);
    ASSERT_TRUE(u.crc_ok);
    EXPECT_GE(u.wall_us, t0_wall);
    EXPECT_LE(u.wall_us, t_end_wall);
    EXPECT_GE(u.wall_us, last_time);
    last_time = u.wall_us;
    ASSERT_EQ(u.points_mm.size(), order.size());
    ASSERT_EQ(u.polygons.size(), scene.organ_surface.tris.size());
    std::vector<float> flat;
    for (std::size_t i = 0; i < order.size(); ++i) {
      const Eigen::Vector3d expected = X_RefModel * scene.organ_surface.positions_World_mm.col(order[i]);
      const Eigen::Vector3d got(u.points_mm[i][0], u.points_mm[i][1], u.points_mm[i][2]);
      worst_mm = std::max(worst_mm, (got - expected).norm());
      flat.insert(flat.end(), u.points_mm[i].begin(), u.points_mm[i].end());
    }
    geometries.insert(flat);
  }
  EXPECT_LT(worst_mm, 60.0) << "the organ is not where the registration puts the scene's organ";  // a wrong frame is metres off
  EXPECT_GE(geometries.size(), 2u) << "the organ did not move (gravity sag)";
  const auto tumour = igtl::test::unpack(tumours.back());
  EXPECT_TRUE(tumour.crc_ok);
  if (const char* save = std::getenv("ARNAV_IGTL_SAVE_POLYDATA"); save && tumour.crc_ok)
    save_picture(save, {{igtl::test::unpack(organs.back()), cv::Scalar(150, 175, 230)}, {tumour, cv::Scalar(40, 40, 230)}});
  EXPECT_EQ(tumour.polygons.size(), scene.tumours[0].rest.tris.size());

  const auto host = nlohmann::json::parse(arnav::testing::read_text(p.dir / "host.json"));
  EXPECT_GE(host["surfaces"]["messages"].get<int>(), 20) << host["surfaces"].dump();
  EXPECT_EQ(host["surfaces"]["publish_failures"].get<int>(), 0);
  EXPECT_EQ(host["security"]["mode"], "sealed");
  const auto igtl_stats = nlohmann::json::parse(arnav::testing::read_text(p.dir / "igtl_stats.json"));
  EXPECT_EQ(igtl_stats["surfaces_rejected"].get<int>(), 0) << igtl_stats.dump();
  EXPECT_EQ(igtl_stats["polydata_unknown"].get<int>(), 3) << igtl_stats.dump();
  std::printf("[ hil ] polydata: %zu Organ (%zu distinct), %zu Tumour, worst |organ - registered scene| %.1f mm; host %s; igtl %s\n", organs.size(),
              geometries.size(), tumours.size(), worst_mm, host["surfaces"].dump().c_str(), igtl_stats.dump().c_str());
}

}  // namespace
}  // namespace arnav::hil
