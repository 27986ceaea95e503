#pragma once
// Printable boards at exact physical scale: a PNG at a stated DPI and an SVG whose size
// is given in millimetres. A footer under the board states the scale and carries a
// 50 mm scale bar to check the print with a ruler. The Board frame (board_layout.hpp)
// is unchanged by the footer: it lies below y = 0.
#include <filesystem>
#include <string>

#include <opencv2/core.hpp>

#include "calibration/lib/board_layout.hpp"

namespace arnav::calib {

constexpr double kBoardFooterMm = 14.0;

// Page image (board + footer), CV_8UC1, at dpi dots per inch.
cv::Mat render_board_png(const BoardLayout& layout, double dpi);
std::string render_board_svg(const BoardLayout& layout);
// Writes PNG and SVG; throws CalibError when a file cannot be written or a tag is not
// a square in the z = 0 plane (only planar boards can be printed).
void write_board_files(const BoardLayout& layout, const std::filesystem::path& png,
                       const std::filesystem::path& svg, double dpi);
// Board-frame point (mm) -> page pixel (x right, y down) at dpi.
cv::Point2d board_to_page_px(const BoardLayout& layout, double x_mm, double y_mm, double dpi);

}  // namespace arnav::calib
