#pragma once
// The host's surfaces to OpenIGTLink, whole (docs/igtl.md "POLYDATA"): the real arnav-host
// (live, on LCM udpm inside the bench's private network namespace; no appliance: a model
// without tool inputs steps on the host clock, the organ sagging under the scene's gravity)
// publishing surface_mesh_t, and the real arnav-igtl serving them as POLYDATA on
// 127.0.0.1. Used by hil_igtl_polydata_e2e_test and arnav-igtl-polydata-bench; the caller
// enters the namespaces first (enter_bench_namespaces).
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include <Eigen/Geometry>

#include "calibration/lib/rigid_transform_file.hpp"
#include "hil_tests/bench/child_process.hpp"
#include "protocol/seal/key.hpp"

namespace arnav::hil {

struct SurfacePipelineOptions {
  std::string host_exe, igtl_exe;
  std::string scene_path;           // absolute
  double model_rate_hz = 60.0;
  double publish_rate_hz = 10.0;    // surfaces.publish_rate_hz
  bool gravity = true;              // the organ sags from the CT shape: a deforming organ
  bool sealed = true;               // the sealed bus (docs/security.md): a fresh key in DIR/bus.key for both programs
};

// The registration the pipeline's session uses: Model -> Ref, turned and ~1.4 m away.
inline Eigen::Isometry3d surface_pipeline_X_RefModel() {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = Eigen::AngleAxisd(0.6, Eigen::Vector3d(0.3, -0.2, 1.0).normalized()).toRotationMatrix();
  X.translation() = Eigen::Vector3d(-120.0, 35.0, -1400.0);
  return X;
}

struct SurfacePipeline {
  std::filesystem::path dir;
  std::unique_ptr<ChildProcess> host, igtl;
  int port = 0;

  // Writes DIR/session.yaml and DIR/X_RefModel.yaml, starts arnav-host (waits for its
  // "session ready") and arnav-igtl (waits for READY). "" or why not (logs in DIR).
  std::string start(const std::filesystem::path& folder, const SurfacePipelineOptions& o) {
    dir = folder;
    std::filesystem::create_directories(dir);
    calib::RigidTransformRecord reg;
    reg.parent_frame = "Ref";
    reg.child_frame = "Model";
    reg.X_ParentChild = surface_pipeline_X_RefModel();
    reg.method = "surface pipeline bench";
    reg.date = "2026-12-02T00:00:00Z";
    calib::write_transform(dir / "X_RefModel.yaml", reg);
    if (o.sealed) {
      std::filesystem::remove(dir / "bus.key");
      seal::write_new_key((dir / "bus.key").string());
    }
    {
      std::ofstream s(dir / "session.yaml");
      s << "arnav_session_version: 1\nlcm_url: \"" << kLcmUrl << "\"\nsecurity: " << (o.sealed ? "{key_file: bus.key}" : "off")
        << "\nscene: " << o.scene_path << "\n"
        << "registration: X_RefModel.yaml\nmodel: {rate_hz: " << o.model_rate_hz << ", gravity: " << (o.gravity ? "true" : "false")
        << "}\nsurfaces: {publish_rate_hz: " << o.publish_rate_hz << "}\n";
    }
    host = std::make_unique<ChildProcess>(std::vector<std::string>{o.host_exe, (dir / "session.yaml").string(), "--quiet", "--summary-json",
                                                                   (dir / "host.json").string()},
                                          std::vector<std::string>{}, (dir / "host.log").string(), true);
    bool ready = false;
    for (int i = 0; i < 300 && !ready; ++i) {
      const auto line = host->read_line(1.0);
      if (line && line->find("session ready") != std::string::npos) ready = true;
      if (!line && !host->running()) break;
    }
    if (!ready) return "arnav-host did not get ready:\n" + host->log_tail();
    igtl = std::make_unique<ChildProcess>(
        std::vector<std::string>{o.igtl_exe, "--lcm", std::string(kLcmUrl) + "&recv_buf_size=4194304", o.sealed ? "--key" : "--security",
                                 o.sealed ? (dir / "bus.key").string() : "off", "--port", "0",
                                 "--stats-json", (dir / "igtl_stats.json").string()},
        std::vector<std::string>{}, (dir / "igtl.log").string(), true);
    const auto line = igtl->read_line(30.0);
    if (!line || line->rfind("READY ", 0) != 0) return "arnav-igtl did not print READY:\n" + igtl->log_tail();
    port = std::stoi(line->substr(6));
    return "";
  }

  static constexpr const char* kLcmUrl = "udpm://239.255.76.67:7667?ttl=0";
};

}  // namespace arnav::hil
