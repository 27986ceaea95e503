#include "appliance/markers/calibration_files.hpp"

#include <cmath>
#include <stdexcept>

namespace arnav::markers {

TagBoard board_from_layout(const calib::BoardLayout& layout, const std::string& tool_name, const std::string& source) {
  if (layout.type == calib::BoardType::Chessboard || layout.tags.empty()) {
    throw std::invalid_argument(source + ": board '" + layout.name +
                                "' has no AprilTags (a chessboard cannot be tracked as a tool)");
  }
  TagBoard board;
  board.name = tool_name;
  board.family = layout.tag_family;
  if (layout.board_width_mm > 0 && layout.board_height_mm > 0) {
    board.paper_mm = Eigen::AlignedBox2d(Eigen::Vector2d(0, 0), Eigen::Vector2d(layout.board_width_mm, layout.board_height_mm));
  }
  for (const auto& t : layout.tags) {
    const auto& c = t.p_BoardCorner_mm;
    const Eigen::Vector3d centre = 0.25 * (c[0] + c[1] + c[2] + c[3]);
    const Eigen::Vector3d ex = (c[1] - c[0] + c[2] - c[3]).normalized();
    const Eigen::Vector3d ey_raw = (c[3] - c[0] + c[2] - c[1]);
    const Eigen::Vector3d ez = ex.cross(ey_raw).normalized();
    const Eigen::Vector3d ey = ez.cross(ex);
    BoardTag tag;
    tag.id = t.id;
    tag.size_mm = 0.5 * ((c[1] - c[0]).norm() + (c[2] - c[3]).norm());
    tag.X_BoardTag.linear() << ex, ey, ez;
    tag.X_BoardTag.translation() = centre;
    // The corners must be the square the tag frame predicts (to 0.01 mm).
    const auto expected = tag_corners_in_board(tag);
    for (size_t k = 0; k < 4; ++k) {
      if ((expected[k] - c[k]).norm() > 0.01) {
        throw std::invalid_argument(source + ": tag " + std::to_string(t.id) + " of board '" + layout.name +
                                    "': corners are not a square in detector order (corner " + std::to_string(k) +
                                    " off by " + std::to_string((expected[k] - c[k]).norm()) + " mm)");
      }
    }
    board.tags.push_back(tag);
  }
  try {
    validate(board);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(source + ": " + e.what());
  }
  return board;
}

TagBoard read_board(const std::filesystem::path& path, const std::string& tool_name) {
  return board_from_layout(calib::read_board_layout(path), tool_name, path.string());
}

CameraModel camera_from_intrinsics(const calib::CameraIntrinsics& intrinsics) {
  CameraModel cam;
  cam.width = intrinsics.image_width;
  cam.height = intrinsics.image_height;
  cam.K = intrinsics.camera_matrix;
  cam.distortion = intrinsics.distortion;
  return cam;
}

CameraModel read_camera(const std::filesystem::path& path) {
  CameraModel cam = camera_from_intrinsics(calib::read_intrinsics(path));
  try {
    validate(cam);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(path.string() + ": " + e.what());
  }
  return cam;
}

}  // namespace arnav::markers
