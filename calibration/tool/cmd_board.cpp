// arnav-calib board: printable board (PNG at a stated DPI + SVG in mm) and its layout.
#include <memory>

#include "calibration/lib/board_layout.hpp"
#include "calibration/lib/board_render.hpp"
#include "calibration/lib/calib_error.hpp"
#include "calibration/tool/commands.hpp"
#include "calibration/tool/report.hpp"

namespace arnav::calib::tool {

namespace {
struct BoardArgs {
  std::string type = "grid";
  std::string family = "tag36h11";
  int cols = 6, rows = 5, first_id = 0;
  double tag_size_mm = 30.0, spacing_mm = 8.0, margin_mm = 10.0, square_mm = 25.0, gap_mm = 50.0, dpi = 300.0;
  std::string out = ".";
};
}  // namespace

Run add_board_command(CLI::App& app) {
  auto a = std::make_shared<BoardArgs>();
  CLI::App* c = app.add_subcommand("board", "Write a printable calibration board (PNG + SVG at exact scale) and its layout YAML");
  c->add_option("--type", a->type, "grid (AprilTag grid), marker (rigid marker board of the hybrid target) or chessboard")
      ->check(CLI::IsMember({"grid", "marker", "chessboard"}))->capture_default_str();
  c->add_option("--family", a->family, "AprilTag family")->check(CLI::IsMember({"tag36h11", "tag25h9", "tag16h5"}))->capture_default_str();
  c->add_option("--cols", a->cols, "grid: tags across; chessboard: inner corners across")->capture_default_str();
  c->add_option("--rows", a->rows, "grid: tags down; chessboard: inner corners down")->capture_default_str();
  c->add_option("--tag-size", a->tag_size_mm, "tag black border edge, mm")->capture_default_str();
  c->add_option("--spacing", a->spacing_mm, "grid: gap between black borders, mm")->capture_default_str();
  c->add_option("--gap", a->gap_mm, "marker board: free centre between the 4 tags (NDI spheres), mm")->capture_default_str();
  c->add_option("--square", a->square_mm, "chessboard square edge, mm")->capture_default_str();
  c->add_option("--first-id", a->first_id, "first tag id")->capture_default_str();
  c->add_option("--margin", a->margin_mm, "white margin around the board, mm")->capture_default_str();
  c->add_option("--dpi", a->dpi, "PNG resolution (dots per inch)")->capture_default_str();
  c->add_option("--out", a->out, "output folder")->capture_default_str();
  return [a] {
    BoardLayout b;
    if (a->type == "grid") {
      b = make_apriltag_grid(a->family, a->cols, a->rows, a->tag_size_mm, a->spacing_mm, a->first_id, a->margin_mm);
    } else if (a->type == "marker") {
      b = make_marker_board(a->family, a->tag_size_mm, a->gap_mm, a->first_id, a->margin_mm);
    } else {
      b = make_chessboard(a->cols, a->rows, a->square_mm, a->margin_mm);
    }
    const auto dir = prepare_out_dir(a->out);
    Report r(dir, "board");
    r.kv("board", b.name, " (", to_string(b.type), ")");
    r.kv("printed size", b.board_width_mm, " x ", b.board_height_mm, " mm + ", kBoardFooterMm, " mm footer");
    if (b.type == BoardType::Chessboard) {
      r.kv("inner corners", b.chessboard->inner_corners_cols, " x ", b.chessboard->inner_corners_rows, ", square ",
           b.chessboard->square_size_mm, " mm");
    } else {
      r.kv("tags", b.tags.size(), " x ", b.tag_family, ", black border ", b.tag_size_mm, " mm, ids ", b.tags.front().id,
           "..", b.tags.back().id);
    }
    const auto layout = dir / (b.name + ".yaml");
    const auto png = dir / (b.name + ".png");
    const auto svg = dir / (b.name + ".svg");
    write_board_layout(layout, b);
    write_board_files(b, png, svg, a->dpi);
    r.file(layout, "layout: what the detector and calibrations read");
    r.file(png, "print image at " + std::to_string(static_cast<int>(a->dpi)) + " dpi");
    r.file(svg, "print image, 1 unit = 1 mm");
    r.line("  PRINT AT 100% (no fit-to-page), then measure the 50 mm bar and one tag/square with a ruler;");
    r.line("  if they differ by more than 0.2 mm, fix the printer scaling or edit tag_size_mm in the layout.");
    r.save();
  };
}

}  // namespace arnav::calib::tool
