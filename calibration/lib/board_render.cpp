#include "calibration/lib/board_render.hpp"

#include <cmath>
#include <fstream>
#include <memory>
#include <sstream>

#include <apriltag/apriltag.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h11.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "calibration/lib/calib_error.hpp"

namespace arnav::calib {
namespace {

struct Family {
  apriltag_family_t* f = nullptr;
  void (*destroy)(apriltag_family_t*) = nullptr;
  explicit Family(const std::string& name) {
    if (name == "tag36h11") { f = tag36h11_create(); destroy = tag36h11_destroy; }
    else if (name == "tag25h9") { f = tag25h9_create(); destroy = tag25h9_destroy; }
    else if (name == "tag16h5") { f = tag16h5_create(); destroy = tag16h5_destroy; }
    else throw CalibError("tag family '" + name + "' cannot be printed (tag36h11, tag25h9, tag16h5)");
  }
  ~Family() { destroy(f); }
  Family(const Family&) = delete;
  Family& operator=(const Family&) = delete;
};

// Black cells of one tag as quads in the Board frame (mm): row 0 of the bitmap is the top
// of the printed tag; the tag's own axes come from its corners (p0 bottom-left,
// p1 bottom-right, p3 top-left).
template <typename EmitQuad>
void for_each_black_cell(const Family& fam, const BoardTag& tag, double tag_size_mm, EmitQuad&& emit) {
  const auto& p = tag.p_BoardCorner_mm;
  for (const auto& c : p) {
    if (std::abs(c.z()) > 1e-9) {
      throw CalibError("tag " + std::to_string(tag.id) + " is not in the z = 0 plane: only planar boards print");
    }
  }
  const Eigen::Vector3d centre = 0.25 * (p[0] + p[1] + p[2] + p[3]);
  const Eigen::Vector3d ex = (p[1] - p[0]) / tag_size_mm;
  const Eigen::Vector3d ey = (p[3] - p[0]) / tag_size_mm;
  image_u8_t* bitmap = apriltag_to_image(fam.f, tag.id);
  const int n = fam.f->total_width;
  const double cell = tag_size_mm / fam.f->width_at_border;
  const double half = 0.5 * n * cell;
  for (int r = 0; r < n; ++r) {
    for (int c = 0; c < n; ++c) {
      if (bitmap->buf[r * bitmap->stride + c] >= 128) continue;
      const double x0 = -half + c * cell;
      const double y1 = half - r * cell;  // top edge of the cell (y up)
      std::array<Eigen::Vector2d, 4> quad;
      const double xs[4] = {x0, x0 + cell, x0 + cell, x0};
      const double ys[4] = {y1 - cell, y1 - cell, y1, y1};
      for (int k = 0; k < 4; ++k) quad[static_cast<std::size_t>(k)] = (centre + xs[k] * ex + ys[k] * ey).head<2>();
      emit(quad);
    }
  }
  image_u8_destroy(bitmap);
}

template <typename EmitQuad>
void for_each_black_square(const BoardLayout& b, EmitQuad&& emit) {
  const auto& c = *b.chessboard;
  const double s = c.square_size_mm;
  for (int r = 0; r <= c.inner_corners_rows; ++r) {
    for (int k = 0; k <= c.inner_corners_cols; ++k) {
      if ((r + k) % 2 != 0) continue;
      const double x0 = c.first_corner_mm.x() - s + k * s;
      const double y0 = c.first_corner_mm.y() - s + r * s;
      emit(std::array<Eigen::Vector2d, 4>{Eigen::Vector2d(x0, y0), Eigen::Vector2d(x0 + s, y0),
                                          Eigen::Vector2d(x0 + s, y0 + s), Eigen::Vector2d(x0, y0 + s)});
    }
  }
}

std::string scale_note(const BoardLayout& b) {
  std::ostringstream t;
  t << "ARNav board " << b.name << " - print at 100% (no fit-to-page): ";
  if (b.type == BoardType::Chessboard) {
    t << "square = " << b.chessboard->square_size_mm << " mm";
  } else {
    t << "tag black border = " << b.tag_size_mm << " mm (" << b.tag_family << ")";
  }
  t << "; bar = 50 mm";
  return t.str();
}

}  // namespace

cv::Point2d board_to_page_px(const BoardLayout& b, double x_mm, double y_mm, double dpi) {
  const double ppmm = dpi / 25.4;
  return {x_mm * ppmm, (b.board_height_mm - y_mm) * ppmm};
}

cv::Mat render_board_png(const BoardLayout& b, double dpi) {
  validate_board_layout(b, "board '" + b.name + "'");
  if (!(dpi >= 72.0 && dpi <= 2400.0)) throw CalibError("dpi must be in 72..2400");
  const double ppmm = dpi / 25.4;
  const int width = static_cast<int>(std::lround(b.board_width_mm * ppmm));
  const int height = static_cast<int>(std::lround((b.board_height_mm + kBoardFooterMm) * ppmm));
  if (static_cast<double>(width) * height > 4.0e8) throw CalibError("board image too large at this dpi");
  cv::Mat page(height, width, CV_8UC1, cv::Scalar(255));
  constexpr int kShift = 8;  // sub-pixel polygon vertices
  auto fill = [&](const std::array<Eigen::Vector2d, 4>& quad) {
    std::vector<cv::Point> pts;
    for (const auto& q : quad) {
      // Pixel area convention: pixel (i, j) covers [i, i+1) x [j, j+1); fillConvexPoly
      // treats vertices as pixel centres, hence the -0.5.
      const cv::Point2d px = board_to_page_px(b, q.x(), q.y(), dpi);
      pts.emplace_back(static_cast<int>(std::lround((px.x - 0.5) * (1 << kShift))),
                       static_cast<int>(std::lround((px.y - 0.5) * (1 << kShift))));
    }
    cv::fillConvexPoly(page, pts, cv::Scalar(0), cv::LINE_8, kShift);
  };
  if (b.type == BoardType::Chessboard) {
    for_each_black_square(b, fill);
  } else {
    Family fam(b.tag_family);
    for (const auto& t : b.tags) for_each_black_cell(fam, t, b.tag_size_mm, fill);
  }
  // Footer: scale bar and text.
  const double y_bar = b.board_height_mm + 4.0;
  const cv::Point2d a(5.0 * ppmm, y_bar * ppmm);
  const cv::Point2d e((5.0 + 50.0) * ppmm, (y_bar + 1.5) * ppmm);
  cv::rectangle(page, cv::Rect2d(a, e), cv::Scalar(0), cv::FILLED);
  const double font = 0.12 * ppmm / 3.0;
  cv::putText(page, scale_note(b) + " @ " + std::to_string(static_cast<int>(dpi)) + " dpi",
              cv::Point(static_cast<int>(5.0 * ppmm), static_cast<int>((y_bar + 7.5) * ppmm)),
              cv::FONT_HERSHEY_SIMPLEX, font, cv::Scalar(0), std::max(1, static_cast<int>(font * 1.5)));
  return page;
}

std::string render_board_svg(const BoardLayout& b) {
  validate_board_layout(b, "board '" + b.name + "'");
  const double H = b.board_height_mm + kBoardFooterMm;
  std::ostringstream svg;
  svg.precision(10);
  svg << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      << "<!-- " << scale_note(b) << ". 1 SVG user unit = 1 mm. Board frame: origin at the "
      << "bottom-left corner of the board area, x right, y up. -->\n"
      << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << b.board_width_mm << "mm\" height=\"" << H
      << "mm\" viewBox=\"0 0 " << b.board_width_mm << " " << H << "\" shape-rendering=\"crispEdges\">\n"
      << "<rect x=\"0\" y=\"0\" width=\"" << b.board_width_mm << "\" height=\"" << H << "\" fill=\"white\"/>\n";
  auto quad = [&](const std::array<Eigen::Vector2d, 4>& q) {
    svg << "<polygon fill=\"black\" points=\"";
    for (std::size_t k = 0; k < 4; ++k) svg << (k ? " " : "") << q[k].x() << "," << b.board_height_mm - q[k].y();
    svg << "\"/>\n";
  };
  if (b.type == BoardType::Chessboard) {
    for_each_black_square(b, quad);
  } else {
    Family fam(b.tag_family);
    for (const auto& t : b.tags) for_each_black_cell(fam, t, b.tag_size_mm, quad);
  }
  const double y_bar = b.board_height_mm + 4.0;
  svg << "<rect x=\"5\" y=\"" << y_bar << "\" width=\"50\" height=\"1.5\" fill=\"black\"/>\n"
      << "<text x=\"5\" y=\"" << y_bar + 7.5 << "\" font-family=\"sans-serif\" font-size=\"3\">" << scale_note(b)
      << "</text>\n</svg>\n";
  return svg.str();
}

void write_board_files(const BoardLayout& b, const std::filesystem::path& png, const std::filesystem::path& svg,
                       double dpi) {
  const cv::Mat page = render_board_png(b, dpi);
  if (!cv::imwrite(png.string(), page)) throw CalibError(png.string() + ": cannot write the board image");
  std::ofstream out(svg, std::ios::binary);
  if (!out) throw CalibError(svg.string() + ": cannot write the board SVG");
  out << render_board_svg(b);
  if (!out) throw CalibError(svg.string() + ": write failed");
}

}  // namespace arnav::calib
