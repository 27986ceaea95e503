// arnav-overlay-bench: render time of the AR overlay at a camera resolution (default
// 1280x720 with a barrel lens), on the bundled liver scene: organ veil + outline, tumour,
// margin shell, vessels, scalpel. The camera orbits the organ so every frame differs.
// Prints one JSON object: per stage (geometry, GL draw + read-back, lens warp, composite,
// total) median / p99 / max in ms, and the GL renderer string.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <vector>

#include <CLI/CLI.hpp>
#include <opencv2/imgcodecs.hpp>
#include <nlohmann/json.hpp>

#include "host/overlay/egl_context.hpp"
#include "host/overlay/overlay_geometry.hpp"
#include "host/overlay/overlay_renderer.hpp"
#include "host/mesh/load_error.hpp"
#include "host/scene/scene.hpp"
#include "protocol/guarded_main.hpp"

namespace {

nlohmann::json stats(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const auto q = [&](double f) { return v[std::min(v.size() - 1, static_cast<std::size_t>(f * (v.size() - 1) + 0.5))]; };
  return {{"median_ms", q(0.5)}, {"p99_ms", q(0.99)}, {"max_ms", v.back()}};
}

}  // namespace

static int main_body(int argc, char** argv) {
  CLI::App app{"arnav-overlay-bench: overlay render time on the bundled liver (JSON)"};
  std::string scene_path;
  int width = 1280, height = 720, frames = 300, msaa = 0;
  bool no_distortion = false;
  std::string save_path;
  app.add_option("--scene", scene_path, "scene file (e.g. data/liver/liver_coarse.scene.yaml)")->required();
  app.add_option("--width", width)->check(CLI::Range(64, 4096));
  app.add_option("--height", height)->check(CLI::Range(64, 4096));
  app.add_option("--frames", frames)->check(CLI::Range(10, 100000));
  app.add_option("--msaa", msaa, "multisample count (0 = off)")->check(CLI::Range(0, 16));
  app.add_flag("--no-distortion", no_distortion, "pinhole camera (no warp)");
  app.add_option("--save", save_path, "write the last composited frame (PNG)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  try {
    const arnav::host::Scene scene = arnav::host::load_scene(scene_path);
    using namespace arnav::host::overlay;
    OverlayCamera cam;
    cam.width = width;
    cam.height = height;
    const double f = 0.9 * width;
    cam.K = cv::Matx33d(f, 0, (width - 1) / 2.0, 0, f, (height - 1) / 2.0, 0, 0, 1);
    if (!no_distortion) cam.distortion = {-0.2, 0.05, 0.0, 0.0, 0.0};
    OverlayStyle style;
    style.msaa_samples = msaa;
    OverlayRenderer renderer(cam, style);
    const arnav::host::TriMesh& organ = scene.organ_surface;
    std::vector<arnav::host::TriMesh> margins;
    for (const auto& t : scene.tumours) margins.push_back(offset_surface(t.rest, 5.0));
    Eigen::Vector3d centre = organ.positions_World_mm.rowwise().mean();
    OverlayContent content;
    content.organ = &organ;
    for (const auto& t : scene.tumours) content.tumours.push_back(&t.rest);
    for (const auto& m : margins) content.margins.push_back(&m);
    if (scene.vessels) content.vessels = &scene.vessels->rest;
    std::vector<double> geometry, gl, warp, comp, total, drawn_fraction;
    cv::Mat image(height, width, CV_8UC3, cv::Scalar(60, 80, 120));
    for (int i = 0; i < frames; ++i) {
      const double a = 0.3 * std::sin(2 * M_PI * i / 120.0);
      Eigen::Isometry3d X_CamModel = Eigen::Isometry3d::Identity();
      X_CamModel.linear() = (Eigen::AngleAxisd(a, Eigen::Vector3d::UnitY()) * Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX())).toRotationMatrix();
      X_CamModel.translation() = Eigen::Vector3d(0, 0, 450) - X_CamModel.linear() * centre;
      content.X_CamModel = X_CamModel;
      const Eigen::Vector3d tip = scene.tumours.empty() ? centre : scene.tumours[0].rest_centroid_World_mm;
      content.scalpel_mm = std::array<Eigen::Vector3d, 2>{tip + Eigen::Vector3d(30 + 10 * a, 0, 40), tip + Eigen::Vector3d(40, 0, 120)};
      const auto t0 = std::chrono::steady_clock::now();
      RenderTiming t;
      const cv::Mat overlay = renderer.render(content, &t);
      const auto c0 = std::chrono::steady_clock::now();
      cv::Mat frame = image.clone();
      composite(frame, overlay, t.drawn_px);
      drawn_fraction.push_back(static_cast<double>(t.drawn_px.area()) / (width * height));
      draw_status(frame, {}, 7.5, 5.0, "bench");
      const auto t1 = std::chrono::steady_clock::now();
      geometry.push_back(t.geometry_ms);
      gl.push_back(t.gl_ms);
      warp.push_back(t.warp_ms);
      comp.push_back(std::chrono::duration<double, std::milli>(t1 - c0).count());
      total.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
      if (i + 1 == frames && !save_path.empty() && !cv::imwrite(save_path, frame))
        throw std::runtime_error("cannot write " + save_path);
    }
    nlohmann::json j;
    j["bench"] = "overlay_render";
    j["gl"] = renderer.gl_description();
    j["scene"] = scene_path;
    j["width"] = width;
    j["height"] = height;
    j["msaa"] = msaa;
    j["distortion"] = !no_distortion;
    j["organ_triangles"] = organ.tris.size();
    j["frames"] = frames;
    j["geometry"] = stats(geometry);
    j["gl_draw_readback"] = stats(gl);
    j["lens_warp"] = stats(warp);
    j["composite_and_text"] = stats(comp);
    j["total"] = stats(total);
    {
      // Area of RenderTiming::drawn_px / image area: what read-back, warp and compositing touch.
      std::sort(drawn_fraction.begin(), drawn_fraction.end());
      j["drawn_fraction_of_image"] = {{"min", drawn_fraction.front()}, {"median", drawn_fraction[drawn_fraction.size() / 2]}, {"max", drawn_fraction.back()}};
    }
    std::cout << j.dump(2) << std::endl;
  } catch (const std::exception& e) {
    std::cerr << "arnav-overlay-bench: " << e.what() << "\n";
    return 2;
  }
  return 0;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-overlay-bench", [&] { return main_body(argc, argv); });
}
