#pragma once
// Calibration target layouts: what `arnav-calib board` prints and what the marker
// detector (appliance/markers) and the calibration read. YAML, millimetres.
//
// Board frame: origin at the bottom-left corner of the printed board, x to the right,
// y up the printed sheet, z out of the paper towards the viewer (right-handed; the same
// axes as the Tag frame of appliance/markers).
//
//   arnav_board_version: 1
//   name: grid_5x4_tag36h11_30mm
//   type: apriltag_grid            # apriltag_grid | marker_board | chessboard
//   frame: Board
//   units: mm
//   board_width_mm: 210            # printed extent (white margin included)
//   board_height_mm: 170
//   tag_family: tag36h11           # AprilTag families: tag36h11, tag25h9, tag16h5
//   tag_size_mm: 30                # edge of the BLACK border square (not the white edge)
//   tags:                          # one entry per tag: id and its 4 corners in Board
//     - id: 0
//       corners_mm: [[x, y, z], [x, y, z], [x, y, z], [x, y, z]]
//   chessboard:                    # type chessboard only (no tags then)
//     inner_corners_cols: 9        # inner corners along x
//     inner_corners_rows: 6        # inner corners along y
//     square_size_mm: 25
//     first_corner_mm: [x, y]      # bottom-left inner corner (0,0) in Board, z = 0
//
// Corner order is the AprilTag detector's (apriltag_detection_t::p): looking at the
// printed tag upright, p0 bottom-left, p1 bottom-right, p2 top-right, p3 top-left,
// i.e. tag-centred (-s/2,-s/2), (+s/2,-s/2), (+s/2,+s/2), (-s/2,+s/2) in x-right/y-up.
#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace arnav::calib {

enum class BoardType { AprilTagGrid, MarkerBoard, Chessboard };

struct BoardTag {
  int id = 0;
  std::array<Eigen::Vector3d, 4> p_BoardCorner_mm;  // detector order p0..p3
};

struct ChessboardSpec {
  int inner_corners_cols = 0;
  int inner_corners_rows = 0;
  double square_size_mm = 0.0;
  Eigen::Vector2d first_corner_mm = Eigen::Vector2d::Zero();
};

struct BoardLayout {
  std::string name;
  BoardType type = BoardType::AprilTagGrid;
  double board_width_mm = 0.0;
  double board_height_mm = 0.0;
  std::string tag_family;   // empty for chessboards
  double tag_size_mm = 0.0; // black border edge
  std::vector<BoardTag> tags;
  std::optional<ChessboardSpec> chessboard;

  const BoardTag* find_tag(int id) const;
  // Chessboard inner corners, row by row from first_corner_mm: (c, r) at
  // first_corner + (c, r) * square (the object points for cv::calibrateCamera).
  std::vector<Eigen::Vector3d> chessboard_corners_mm() const;
};

struct TagFamilyInfo {
  const char* name;
  int ncodes;           // valid ids are 0 .. ncodes-1
  int total_width;      // cells, white border included
  int width_at_border;  // cells across the black border (tag_size_mm spans these)
};
// Families ARNav prints and detects; nullptr for an unknown name.
const TagFamilyInfo* find_tag_family(const std::string& name);

std::string to_string(BoardType type);

// Parsing: throws CalibError naming file and line (duplicate ids, bad corners, ...).
BoardLayout read_board_layout(const std::filesystem::path& path);
BoardLayout parse_board_layout(const std::string& yaml_text, const std::string& source);
void write_board_layout(const std::filesystem::path& path, const BoardLayout& layout);
std::string format_board_layout(const BoardLayout& layout);
void validate_board_layout(const BoardLayout& layout, const std::string& source);

// Generators used by `arnav-calib board`.
// Grid of cols x rows tags, ids first_id.. row by row from the top-left as printed;
// spacing between black borders.
BoardLayout make_apriltag_grid(const std::string& family, int cols, int rows, double tag_size_mm,
                               double spacing_mm, int first_id, double margin_mm);
// Rigid marker board for the hybrid camera/NDI target: 2x2 tags around a free centre
// (centre_gap_mm square) where the NDI tool's marker spheres are mounted.
BoardLayout make_marker_board(const std::string& family, double tag_size_mm,
                              double centre_gap_mm, int first_id, double margin_mm);
// Chessboard with inner_cols x inner_rows inner corners (squares: +1 each way).
BoardLayout make_chessboard(int inner_cols, int inner_rows, double square_size_mm,
                            double margin_mm);

}  // namespace arnav::calib
