#include "calibration/lib/board_layout.hpp"

#include <cmath>
#include <fstream>
#include <iomanip>
#include <set>
#include <sstream>

#include <Eigen/Geometry>
#include <yaml-cpp/yaml.h>

#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/versioned_yaml.hpp"

namespace arnav::calib {
namespace {

constexpr TagFamilyInfo kFamilies[] = {
    {"tag36h11", 587, 10, 8},
    {"tag25h9", 35, 9, 7},
    {"tag16h5", 30, 8, 6},
};

std::string where(const std::string& source, const YAML::Node& node) {
  const YAML::Mark mark = node.Mark();
  if (mark.line < 0) return source;
  return source + ":" + std::to_string(mark.line + 1);
}

template <typename T>
T get(const YAML::Node& map, const char* key, const std::string& source) {
  const YAML::Node node = map[key];
  if (!node) throw CalibError(where(source, map) + ": missing key '" + key + "'");
  try {
    return node.as<T>();
  } catch (const YAML::Exception&) {
    throw CalibError(where(source, node) + ": key '" + key + "' has the wrong type");
  }
}

double finite(double v, const std::string& what) {
  if (!std::isfinite(v)) throw CalibError(what + " is not a finite number");
  return v;
}

// Corners of an axis-aligned tag centred at (cx, cy) in detector order.
std::array<Eigen::Vector3d, 4> square_corners(double cx, double cy, double s) {
  const double h = 0.5 * s;
  return {Eigen::Vector3d(cx - h, cy - h, 0), Eigen::Vector3d(cx + h, cy - h, 0),
          Eigen::Vector3d(cx + h, cy + h, 0), Eigen::Vector3d(cx - h, cy + h, 0)};
}

}  // namespace

const TagFamilyInfo* find_tag_family(const std::string& name) {
  for (const auto& f : kFamilies) {
    if (name == f.name) return &f;
  }
  return nullptr;
}

std::string to_string(BoardType type) {
  switch (type) {
    case BoardType::AprilTagGrid: return "apriltag_grid";
    case BoardType::MarkerBoard: return "marker_board";
    case BoardType::Chessboard: return "chessboard";
  }
  return "unknown";
}

const BoardTag* BoardLayout::find_tag(int id) const {
  for (const auto& t : tags) {
    if (t.id == id) return &t;
  }
  return nullptr;
}

std::vector<Eigen::Vector3d> BoardLayout::chessboard_corners_mm() const {
  std::vector<Eigen::Vector3d> pts;
  if (!chessboard) return pts;
  const auto& c = *chessboard;
  for (int r = 0; r < c.inner_corners_rows; ++r) {
    for (int k = 0; k < c.inner_corners_cols; ++k) {
      pts.emplace_back(c.first_corner_mm.x() + k * c.square_size_mm,
                       c.first_corner_mm.y() + r * c.square_size_mm, 0.0);
    }
  }
  return pts;
}

void validate_board_layout(const BoardLayout& b, const std::string& source) {
  auto fail = [&](const std::string& what) { throw CalibError(source + ": " + what); };
  if (b.name.empty()) fail("board name is empty");
  if (!(b.board_width_mm > 0.0) || !(b.board_height_mm > 0.0) || b.board_width_mm > 5000.0 ||
      b.board_height_mm > 5000.0) {
    fail("board_width_mm/board_height_mm must be in (0, 5000] mm");
  }
  if (b.type == BoardType::Chessboard) {
    if (!b.chessboard) fail("a chessboard layout needs a 'chessboard' section");
    const auto& c = *b.chessboard;
    if (c.inner_corners_cols < 2 || c.inner_corners_rows < 2 || c.inner_corners_cols > 100 ||
        c.inner_corners_rows > 100) {
      fail("chessboard needs 2..100 inner corners each way");
    }
    if (c.inner_corners_cols == c.inner_corners_rows) {
      fail("a square chessboard (equal inner corner counts) is ambiguous under 90 degree "
           "rotation; use e.g. 9 x 6");
    }
    if (!(c.square_size_mm > 0.0) || c.square_size_mm > 1000.0) {
      fail("chessboard square_size_mm must be in (0, 1000]");
    }
    if (!b.tags.empty()) fail("a chessboard layout must not list tags");
    return;
  }
  const TagFamilyInfo* fam = find_tag_family(b.tag_family);
  if (!fam) fail("tag_family '" + b.tag_family + "' is not supported (tag36h11, tag25h9, tag16h5)");
  if (!(b.tag_size_mm > 0.0) || b.tag_size_mm > 1000.0) fail("tag_size_mm must be in (0, 1000]");
  if (b.tags.empty()) fail("the board lists no tags");
  std::set<int> ids;
  for (const auto& t : b.tags) {
    const std::string tag = "tag id " + std::to_string(t.id);
    if (t.id < 0 || t.id >= fam->ncodes) {
      fail(tag + " is outside 0.." + std::to_string(fam->ncodes - 1) + " of " + b.tag_family);
    }
    if (!ids.insert(t.id).second) fail(tag + " appears twice (ids must be unique on a board)");
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector3d& a = t.p_BoardCorner_mm[k];
      const Eigen::Vector3d& c = t.p_BoardCorner_mm[(k + 1) % 4];
      if (!a.allFinite()) fail(tag + ": corner is not finite");
      const double edge = (c - a).norm();
      // Printed squares are exact; 1% tolerates a measured (not generated) rigid board.
      if (std::abs(edge - b.tag_size_mm) > 0.01 * b.tag_size_mm) {
        fail(tag + ": corner " + std::to_string(k) + " to " + std::to_string((k + 1) % 4) +
             " is " + std::to_string(edge) + " mm, expected tag_size_mm " +
             std::to_string(b.tag_size_mm));
      }
    }
    const Eigen::Vector3d d02 = t.p_BoardCorner_mm[2] - t.p_BoardCorner_mm[0];
    const Eigen::Vector3d d13 = t.p_BoardCorner_mm[3] - t.p_BoardCorner_mm[1];
    if (std::abs(d02.norm() - d13.norm()) > 0.01 * b.tag_size_mm ||
        std::abs(d02.dot(d13)) > 0.02 * b.tag_size_mm * b.tag_size_mm) {
      fail(tag + ": corners do not form a square");
    }
    // Detector order turns counter-clockwise seen from the front, so the normal
    // (p1-p0) x (p3-p0) points out of the paper (+z) for a tag printed in z = 0.
    const Eigen::Vector3d n = (t.p_BoardCorner_mm[1] - t.p_BoardCorner_mm[0])
                                  .cross(t.p_BoardCorner_mm[3] - t.p_BoardCorner_mm[0]);
    if (n.z() < 0.0 && std::abs(n.z()) > 0.5 * n.norm()) {
      fail(tag + ": corners are listed in mirrored order (expected p0 bottom-left, p1 "
           "bottom-right, p2 top-right, p3 top-left)");
    }
  }
}

BoardLayout parse_board_layout(const std::string& yaml_text, const std::string& source) {
  const YAML::Node root = load_versioned_yaml(yaml_text, source, "an ARNav board layout", "arnav_board_version");
  BoardLayout b;
  b.name = get<std::string>(root, "name", source);
  const std::string type = get<std::string>(root, "type", source);
  if (type == "apriltag_grid") {
    b.type = BoardType::AprilTagGrid;
  } else if (type == "marker_board") {
    b.type = BoardType::MarkerBoard;
  } else if (type == "chessboard") {
    b.type = BoardType::Chessboard;
  } else {
    throw CalibError(where(source, root["type"]) + ": type '" + type +
                     "' unknown (apriltag_grid, marker_board or chessboard)");
  }
  const std::string units = get<std::string>(root, "units", source);
  if (units != "mm") throw CalibError(where(source, root["units"]) + ": units must be mm");
  b.board_width_mm = finite(get<double>(root, "board_width_mm", source), source + ": board_width_mm");
  b.board_height_mm = finite(get<double>(root, "board_height_mm", source), source + ": board_height_mm");
  if (b.type == BoardType::Chessboard) {
    const YAML::Node c = root["chessboard"];
    if (!c || !c.IsMap()) throw CalibError(source + ": missing map 'chessboard'");
    ChessboardSpec spec;
    spec.inner_corners_cols = get<int>(c, "inner_corners_cols", source);
    spec.inner_corners_rows = get<int>(c, "inner_corners_rows", source);
    spec.square_size_mm = finite(get<double>(c, "square_size_mm", source), source + ": square_size_mm");
    const YAML::Node fc = c["first_corner_mm"];
    if (!fc || !fc.IsSequence() || fc.size() != 2) {
      throw CalibError(where(source, c) + ": first_corner_mm must be [x, y]");
    }
    try {
      spec.first_corner_mm = {fc[0].as<double>(), fc[1].as<double>()};
    } catch (const YAML::Exception&) {
      throw CalibError(where(source, fc) + ": first_corner_mm entries must be numbers");
    }
    if (!spec.first_corner_mm.allFinite()) throw CalibError(where(source, fc) + ": not finite");
    b.chessboard = spec;
  } else {
    b.tag_family = get<std::string>(root, "tag_family", source);
    b.tag_size_mm = finite(get<double>(root, "tag_size_mm", source), source + ": tag_size_mm");
    const YAML::Node tags = root["tags"];
    if (!tags || !tags.IsSequence()) throw CalibError(source + ": missing list 'tags'");
    for (const auto& tn : tags) {
      if (!tn.IsMap()) throw CalibError(where(source, tn) + ": each tag is a map {id, corners_mm}");
      BoardTag t;
      t.id = get<int>(tn, "id", source);
      const YAML::Node cs = tn["corners_mm"];
      if (!cs || !cs.IsSequence() || cs.size() != 4) {
        throw CalibError(where(source, tn) + ": tag " + std::to_string(t.id) +
                         ": corners_mm must list 4 corners [x, y, z]");
      }
      for (std::size_t k = 0; k < 4; ++k) {
        const YAML::Node p = cs[k];
        if (!p.IsSequence() || p.size() != 3) {
          throw CalibError(where(source, p) + ": tag " + std::to_string(t.id) + " corner " +
                           std::to_string(k) + " must be [x, y, z]");
        }
        try {
          t.p_BoardCorner_mm[k] = {p[0].as<double>(), p[1].as<double>(), p[2].as<double>()};
        } catch (const YAML::Exception&) {
          throw CalibError(where(source, p) + ": tag " + std::to_string(t.id) + " corner " +
                           std::to_string(k) + " has a non-number entry");
        }
      }
      // Check each tag where it is written so the error names its line.
      validate_board_layout(BoardLayout{b.name, b.type, 1.0, 1.0, b.tag_family, b.tag_size_mm, {t}, {}},
                            where(source, tn));
      b.tags.push_back(t);
    }
  }
  validate_board_layout(b, source);
  return b;
}

BoardLayout read_board_layout(const std::filesystem::path& path) {
  return parse_board_layout(read_text_file(path, "the board layout (make one with `arnav-calib board`)"),
                            path.string());
}

std::string format_board_layout(const BoardLayout& b) {
  validate_board_layout(b, "board '" + b.name + "'");
  std::ostringstream out;
  out << std::setprecision(12);
  out << "# ARNav board layout (docs/calibration.md). Board frame: origin bottom-left of the\n"
         "# printed board, x right, y up the sheet, z out of the paper; millimetres.\n";
  if (b.type != BoardType::Chessboard) {
    out << "# Tag corners in AprilTag detector order: p0 bottom-left, p1 bottom-right,\n"
           "# p2 top-right, p3 top-left (tag upright); tag_size_mm = black border edge.\n";
  }
  out << "arnav_board_version: 1\n";
  out << "name: " << b.name << "\n";
  out << "type: " << to_string(b.type) << "\n";
  out << "frame: Board\nunits: mm\n";
  out << "board_width_mm: " << b.board_width_mm << "\n";
  out << "board_height_mm: " << b.board_height_mm << "\n";
  if (b.type == BoardType::Chessboard) {
    const auto& c = *b.chessboard;
    out << "chessboard:\n";
    out << "  inner_corners_cols: " << c.inner_corners_cols << "\n";
    out << "  inner_corners_rows: " << c.inner_corners_rows << "\n";
    out << "  square_size_mm: " << c.square_size_mm << "\n";
    out << "  first_corner_mm: [" << c.first_corner_mm.x() << ", " << c.first_corner_mm.y() << "]\n";
  } else {
    out << "tag_family: " << b.tag_family << "\n";
    out << "tag_size_mm: " << b.tag_size_mm << "\n";
    out << "tags:\n";
    for (const auto& t : b.tags) {
      out << "  - id: " << t.id << "\n    corners_mm: [";
      for (int k = 0; k < 4; ++k) {
        const auto& p = t.p_BoardCorner_mm[k];
        out << (k ? ", " : "") << "[" << p.x() << ", " << p.y() << ", " << p.z() << "]";
      }
      out << "]\n";
    }
  }
  return out.str();
}

void write_board_layout(const std::filesystem::path& path, const BoardLayout& b) {
  const std::string text = format_board_layout(b);
  std::ofstream out(path, std::ios::binary);
  if (!out) throw CalibError(path.string() + ": cannot write the board layout");
  out << text;
  if (!out) throw CalibError(path.string() + ": write failed");
}

BoardLayout make_apriltag_grid(const std::string& family, int cols, int rows, double tag_size_mm,
                               double spacing_mm, int first_id, double margin_mm) {
  const TagFamilyInfo* fam = find_tag_family(family);
  if (!fam) throw CalibError("tag family '" + family + "' is not supported (tag36h11, tag25h9, tag16h5)");
  if (cols < 1 || rows < 1 || cols * rows > 1000) throw CalibError("grid needs 1..1000 tags");
  const double cell = tag_size_mm / fam->width_at_border;
  if (spacing_mm < cell) {
    throw CalibError("tag spacing " + std::to_string(spacing_mm) + " mm leaves no white border " +
                     "between tags; use at least one cell (" + std::to_string(cell) + " mm)");
  }
  if (first_id < 0 || first_id + cols * rows > fam->ncodes) {
    throw CalibError("ids " + std::to_string(first_id) + ".." +
                     std::to_string(first_id + cols * rows - 1) + " exceed " + family + "'s " +
                     std::to_string(fam->ncodes) + " codes");
  }
  // The white quiet zone of one cell around each tag lies inside the margin.
  const double border = margin_mm + cell;
  BoardLayout b;
  std::ostringstream name;
  name << "grid_" << cols << "x" << rows << "_" << family << "_" << tag_size_mm << "mm";
  b.name = name.str();
  b.type = BoardType::AprilTagGrid;
  b.tag_family = family;
  b.tag_size_mm = tag_size_mm;
  b.board_width_mm = 2 * border + cols * tag_size_mm + (cols - 1) * spacing_mm;
  b.board_height_mm = 2 * border + rows * tag_size_mm + (rows - 1) * spacing_mm;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      const double cx = border + c * (tag_size_mm + spacing_mm) + 0.5 * tag_size_mm;
      // Row 0 is printed at the top; y points up the sheet.
      const double cy = b.board_height_mm - border - r * (tag_size_mm + spacing_mm) - 0.5 * tag_size_mm;
      b.tags.push_back({first_id + r * cols + c, square_corners(cx, cy, tag_size_mm)});
    }
  }
  validate_board_layout(b, "generated grid");
  return b;
}

BoardLayout make_marker_board(const std::string& family, double tag_size_mm, double centre_gap_mm,
                              int first_id, double margin_mm) {
  if (!(centre_gap_mm >= 0.0)) throw CalibError("centre gap must be >= 0 mm");
  BoardLayout b = make_apriltag_grid(family, 2, 2, tag_size_mm, centre_gap_mm, first_id, margin_mm);
  std::ostringstream name;
  name << "marker_board_" << family << "_" << tag_size_mm << "mm_ids" << first_id << "-"
       << first_id + 3;
  b.name = name.str();
  b.type = BoardType::MarkerBoard;
  return b;
}

BoardLayout make_chessboard(int inner_cols, int inner_rows, double square_size_mm,
                            double margin_mm) {
  BoardLayout b;
  std::ostringstream name;
  name << "chessboard_" << inner_cols << "x" << inner_rows << "_" << square_size_mm << "mm";
  b.name = name.str();
  b.type = BoardType::Chessboard;
  b.board_width_mm = 2 * margin_mm + (inner_cols + 1) * square_size_mm;
  b.board_height_mm = 2 * margin_mm + (inner_rows + 1) * square_size_mm;
  b.chessboard = ChessboardSpec{inner_cols, inner_rows, square_size_mm,
                                Eigen::Vector2d(margin_mm + square_size_mm, margin_mm + square_size_mm)};
  validate_board_layout(b, "generated chessboard");
  return b;
}

}  // namespace arnav::calib
