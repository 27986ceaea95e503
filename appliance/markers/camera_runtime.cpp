#include "appliance/markers/camera_runtime.hpp"

#include <fstream>
#include <sstream>

namespace arnav::camera {

CameraRuntime::CameraRuntime(CameraConfig config, std::shared_ptr<frames::ReferenceFrames> frames)
    : config_(std::move(config)), frames_(std::move(frames)) {}

std::unique_ptr<CameraRuntime> CameraRuntime::load(const std::filesystem::path& config_file) {
  std::ifstream in(config_file);
  if (!in) throw CameraConfigError(config_file.string() + ": cannot open the configuration file");
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string source = config_file.string();
  const std::filesystem::path base = config_file.parent_path().empty() ? std::filesystem::path(".") : config_file.parent_path();
  std::optional<CameraConfig> cam = parse_camera_config(ss.str(), source, base);
  if (!cam) return nullptr;
  const frames::FramesConfig fc = parse_frames_config(ss.str(), source, base);
  std::shared_ptr<frames::ReferenceFrames> frames;
  try {
    frames = frames::ReferenceFrames::load(fc);
  } catch (const std::invalid_argument& e) {
    throw CameraConfigError(source + ": frames: " + e.what());
  }
  return std::unique_ptr<CameraRuntime>(new CameraRuntime(std::move(*cam), std::move(frames)));
}

std::string CameraRuntime::summary() const {
  std::string tools;
  for (const auto& t : config_.tools) tools += (tools.empty() ? "" : ", ") + t.board.name;
  return "camera '" + config_.name + "' " + make_source(config_)->describe() + ", tools: " + tools + ", reference " +
         frames::to_string(frames_->reference());
}

void CameraRuntime::start(const std::string& lcm_url) {
  if (pipeline_) return;
  pipeline_ = std::make_unique<CameraPipeline>(config_, frames_, lcm_url);
  pipeline_->start();
}

void CameraRuntime::stop() {
  if (pipeline_) pipeline_->stop();
}

}  // namespace arnav::camera
