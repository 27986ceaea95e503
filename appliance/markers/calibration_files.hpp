#pragma once
// Bridges from the calibration library's files (calibration/lib) to the marker types:
// board layouts (arnav-calib board) and camera intrinsics (FileStorage YAML).
#include <filesystem>
#include <string>

#include "appliance/markers/camera_model.hpp"
#include "appliance/markers/tag_board.hpp"
#include "calibration/lib/board_layout.hpp"
#include "calibration/lib/camera_intrinsics.hpp"

namespace arnav::markers {

// Tags placed from their four corners (which must form a square in the layout's z = 0
// plane). Throws std::invalid_argument naming `source` for a chessboard or a bent tag.
TagBoard board_from_layout(const calib::BoardLayout& layout, const std::string& tool_name, const std::string& source);
// Reads the layout file (errors name file and line) and converts it.
TagBoard read_board(const std::filesystem::path& path, const std::string& tool_name);

CameraModel camera_from_intrinsics(const calib::CameraIntrinsics& intrinsics);
CameraModel read_camera(const std::filesystem::path& path);

}  // namespace arnav::markers
