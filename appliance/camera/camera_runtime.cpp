#include "appliance/camera/camera_runtime.hpp"

#include <fstream>
#include <sstream>

namespace arnav::camera {

CameraRuntime::CameraRuntime(CameraConfig config, std::shared_ptr<frames::ReferenceFrames> frames)
    : config_(std::move(config)), frames_(std::move(frames)) {}

namespace {
struct ConfigText {
  std::string text, source;
  std::filesystem::path base;
};
ConfigText read_config(const std::filesystem::path& config_file) {
  std::ifstream in(config_file);
  if (!in) throw CameraConfigError(config_file.string() + ": cannot open the configuration file");
  std::stringstream ss;
  ss << in.rdbuf();
  return {ss.str(), config_file.string(),
          config_file.parent_path().empty() ? std::filesystem::path(".") : config_file.parent_path()};
}
std::shared_ptr<frames::ReferenceFrames> frames_from(const ConfigText& c) {
  const frames::FramesConfig fc = parse_frames_config(c.text, c.source, c.base);
  try {
    return frames::ReferenceFrames::load(fc);
  } catch (const std::invalid_argument& e) {
    throw CameraConfigError(c.source + ": frames: " + e.what());
  }
}
}  // namespace

std::unique_ptr<CameraRuntime> CameraRuntime::load(const std::filesystem::path& config_file) {
  const ConfigText c = read_config(config_file);
  std::optional<CameraConfig> cam = parse_camera_config(c.text, c.source, c.base);
  if (!cam) return nullptr;
  return std::unique_ptr<CameraRuntime>(new CameraRuntime(std::move(*cam), frames_from(c)));
}

std::shared_ptr<frames::ReferenceFrames> CameraRuntime::load_frames(const std::filesystem::path& config_file) {
  return frames_from(read_config(config_file));
}

std::string CameraRuntime::summary() const {
  std::string tools;
  for (const auto& t : config_.tools) tools += (tools.empty() ? "" : ", ") + t.board.name;
  return "camera '" + config_.name + "' " + make_source(config_)->describe() + ", tools: " + tools + ", reference " +
         frames::to_string(frames_->reference());
}

void CameraRuntime::start(const std::string& lcm_url, const seal::BusSecurity& security) {
  if (pipeline_) return;
  pipeline_ = std::make_unique<CameraPipeline>(config_, frames_, lcm_url, security);
  pipeline_->start();
}

void CameraRuntime::stop() {
  if (pipeline_) pipeline_->stop();
}

}  // namespace arnav::camera
