#include "appliance/synthetic_camera/synthetic_renderer.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <stdexcept>

#include "appliance/markers/tag_family.hpp"

namespace arnav::camera_sim {

struct SyntheticRenderer::BitmapCache {
  std::mutex mutex;
  std::map<std::string, std::unique_ptr<markers::TagFamily>> families;
  std::map<std::pair<std::string, int>, cv::Mat> cells;

  // Returns the cell grid and the family's border width (cells across the black square).
  std::pair<cv::Mat, int> get(const std::string& family, int id) {
    std::lock_guard lock(mutex);
    auto& fam = families[family];
    if (!fam) fam = std::make_unique<markers::TagFamily>(family);
    auto& c = cells[{family, id}];
    if (c.empty()) c = fam->cells(id);
    return {c, fam->width_at_border()};
  }
};

namespace {

// One tag prepared for lookups in board-plane coordinates.
struct TagLookup {
  double r00 = 1, r10 = 0, r01 = 0, r11 = 1, tx = 0, ty = 0;  // board -> tag in-plane transform
  double cell_mm = 1;
  int total = 0;
  cv::Mat cells;
};

struct Region {
  int id;        // -1 outside the paper, 0 paper, > 0 a tag cell
  float value;   // reflectance
  int tag;       // index of the tag, -1 if none
};

}  // namespace

SyntheticRenderer::SyntheticRenderer(markers::CameraModel camera)
    : camera_(std::move(camera)), bitmaps_(std::make_unique<BitmapCache>()) {
  markers::validate(camera_);
  std::vector<cv::Point2d> corners;
  corners.reserve(static_cast<size_t>((camera_.width + 1) * (camera_.height + 1)));
  for (int j = 0; j <= camera_.height; ++j) {
    for (int i = 0; i <= camera_.width; ++i) corners.emplace_back(i - 0.5, j - 0.5);
  }
  const std::vector<cv::Point2d> rays = camera_.normalised(corners);
  rays_.create(camera_.height + 1, camera_.width + 1, CV_64FC2);
  for (int j = 0; j <= camera_.height; ++j) {
    for (int i = 0; i <= camera_.width; ++i) {
      const cv::Point2d& r = rays[static_cast<size_t>(j * (camera_.width + 1) + i)];
      rays_.at<cv::Vec2d>(j, i) = cv::Vec2d(r.x, r.y);
    }
  }
}

SyntheticRenderer::~SyntheticRenderer() = default;

RenderResult SyntheticRenderer::render(const std::vector<BoardInScene>& scene, const RenderOptions& options) const {
  return render(scene, {}, options);
}

RenderResult SyntheticRenderer::render(const std::vector<BoardInScene>& scene, const std::vector<SurfaceInScene>& surfaces,
                                       const RenderOptions& options) const {
  const int W = camera_.width;
  const int H = camera_.height;
  const int ss = std::max(1, options.supersample);
  cv::Mat refl(H, W, CV_32F, cv::Scalar(options.background_reflectance));
  RenderResult result;

  // Surfaces: painter's order with a per-pixel depth (the drawn triangle's mean depth) so
  // boards can be composed by depth below.
  cv::Mat surface_z;
  if (!surfaces.empty()) {
    constexpr int kShift = 4;  // sub-pixel vertex positions for fillConvexPoly
    surface_z = cv::Mat(H, W, CV_32F, cv::Scalar(static_cast<double>(std::numeric_limits<float>::infinity())));
    result.surface_mask = cv::Mat::zeros(H, W, CV_8U);
    struct Tri {
      double depth;
      std::array<cv::Point, 3> px;
      float shade;
    };
    std::vector<Tri> tris;
    for (const auto& s : surfaces) {
      if (s.vertices_Cam_mm == nullptr || s.faces == nullptr) throw std::invalid_argument("synthetic renderer: surface without vertices or faces");
      const Eigen::Matrix3Xd& V = *s.vertices_Cam_mm;
      std::vector<Eigen::Vector3d> pts(static_cast<size_t>(V.cols()));
      for (Eigen::Index i = 0; i < V.cols(); ++i) pts[static_cast<size_t>(i)] = V.col(i);
      const auto px = camera_.project(pts);
      for (const auto& f : *s.faces) {
        for (int k = 0; k < 3; ++k)
          if (f[k] < 0 || f[k] >= V.cols()) throw std::invalid_argument("synthetic renderer: surface face index out of range");
        const Eigen::Vector3d a = V.col(f[0]), b = V.col(f[1]), c = V.col(f[2]);
        if (a.z() <= 1.0 || b.z() <= 1.0 || c.z() <= 1.0) continue;  // at or behind the lens
        const Eigen::Vector3d centre = (a + b + c) / 3.0;
        const Eigen::Vector3d n = (b - a).cross(c - a);
        const double nn = n.norm();
        if (!(nn > 0.0) || n.dot(centre) >= 0.0) continue;  // degenerate or facing away
        Tri t;
        t.depth = centre.z();
        const double cos_view = std::abs(n.dot(centre)) / (nn * centre.norm());
        t.shade = static_cast<float>(s.reflectance * (0.3 + 0.7 * cos_view));
        for (int k = 0; k < 3; ++k) {
          const cv::Point2d& q = px[static_cast<size_t>(f[k])];
          if (!std::isfinite(q.x) || !std::isfinite(q.y) || std::abs(q.x) > 1e6 || std::abs(q.y) > 1e6) {
            t.depth = -1.0;
            break;
          }
          t.px[static_cast<size_t>(k)] = cv::Point(cvRound(q.x * (1 << kShift)), cvRound(q.y * (1 << kShift)));
        }
        if (t.depth > 0.0) tris.push_back(t);
      }
    }
    std::sort(tris.begin(), tris.end(), [](const Tri& x, const Tri& y) { return x.depth > y.depth; });
    for (const auto& t : tris) {
      cv::fillConvexPoly(refl, t.px.data(), 3, cv::Scalar(t.shade), cv::LINE_8, kShift);
      cv::fillConvexPoly(surface_z, t.px.data(), 3, cv::Scalar(static_cast<double>(t.depth)), cv::LINE_8, kShift);
      cv::fillConvexPoly(result.surface_mask, t.px.data(), 3, cv::Scalar(255), cv::LINE_8, kShift);
    }
  }

  cv::Mat occ_mask = cv::Mat::zeros(H, W, CV_8U);
  for (const auto& occ : options.occluders) {
    std::vector<cv::Point> poly;
    for (const auto& p : occ.polygon_px) poly.emplace_back(cvRound(p.x), cvRound(p.y));
    if (poly.size() >= 3) cv::fillPoly(occ_mask, std::vector<std::vector<cv::Point>>{poly}, cv::Scalar(255));
  }

  for (const auto& item : scene) {
    if (item.board == nullptr) throw std::invalid_argument("synthetic renderer: scene entry without a board");
    const markers::TagBoard& board = *item.board;
    const Eigen::Matrix3d R = item.X_CamBoard.linear();
    const Eigen::Vector3d o = item.X_CamBoard.translation();
    const Eigen::Vector3d ex = R.col(0), ey = R.col(1), n = R.col(2);
    markers::validate(board);  // planar, tags on one side
    // The printed side is the tags' front (board +z or -z, see markers::front_side).
    const bool facing = markers::front_side(board) * n.dot(-o) > 0.0;

    std::vector<TagLookup> tags;
    double min_cell_mm = 1e300;
    for (const auto& tag : board.tags) {
      const Eigen::Matrix3d Rt = tag.X_BoardTag.linear();
      auto [cells, border] = bitmaps_->get(board.family, tag.id);
      TagLookup t;
      t.r00 = Rt(0, 0);
      t.r10 = Rt(1, 0);
      t.r01 = Rt(0, 1);
      t.r11 = Rt(1, 1);
      t.tx = tag.X_BoardTag.translation().x();
      t.ty = tag.X_BoardTag.translation().y();
      t.cell_mm = tag.size_mm / border;
      t.total = cells.cols;
      t.cells = cells;
      tags.push_back(t);
      min_cell_mm = std::min(min_cell_mm, t.cell_mm);
    }
    // Without a printed outline the sheet spans every tag's whole bitmap (for families
    // with data bits outside the border that is wider than the border square) + margin.
    Eigen::AlignedBox2d paper = board.paper_mm;
    if (paper.isEmpty()) {
      for (size_t k = 0; k < tags.size(); ++k) {
        const double half = 0.5 * tags[k].total * tags[k].cell_mm + options.paper_margin_mm;
        for (const auto& c : markers::tag_corners_in_tag(2.0 * half)) {
          paper.extend((board.tags[k].X_BoardTag * c).head<2>());
        }
      }
    }
    const float paper_value = static_cast<float>(facing ? options.paper_reflectance : 0.8 * options.paper_reflectance);
    const float black_value = static_cast<float>(options.black_reflectance);

    auto classify = [&](double bx, double by) -> Region {
      if (!std::isfinite(bx) || !paper.contains(Eigen::Vector2d(bx, by))) return {-1, 0.f, -1};
      if (facing) {
        for (size_t k = 0; k < tags.size(); ++k) {
          const TagLookup& t = tags[k];
          const double dx = bx - t.tx, dy = by - t.ty;
          const double lx = t.r00 * dx + t.r10 * dy;
          const double ly = t.r01 * dx + t.r11 * dy;
          // Tag frame y is up, bitmap rows go down.
          const double cu = lx / t.cell_mm + 0.5 * t.total;
          const double cv_ = -ly / t.cell_mm + 0.5 * t.total;
          if (cu >= 0 && cv_ >= 0 && cu < t.total && cv_ < t.total) {
            const int c = static_cast<int>(cu), r = static_cast<int>(cv_);
            const bool white = t.cells.at<std::uint8_t>(r, c) > 127;
            return {1 + static_cast<int>(k) * 4096 + r * 64 + c, white ? paper_value : black_value, static_cast<int>(k)};
          }
        }
      }
      return {0, paper_value, -1};
    };

    // Image bounding box of the paper (edges sampled: distortion bends them).
    int x0 = 0, y0 = 0, x1 = W - 1, y1 = H - 1;
    {
      std::vector<Eigen::Vector3d> outline;
      const Eigen::Vector2d a = paper.min(), b = paper.max();
      constexpr int kSteps = 24;
      bool behind = false, all_behind = true;
      for (int s = 0; s <= kSteps; ++s) {
        const double f = static_cast<double>(s) / kSteps;
        for (const Eigen::Vector2d& q : {Eigen::Vector2d(a.x() + f * (b.x() - a.x()), a.y()),
                                         Eigen::Vector2d(a.x() + f * (b.x() - a.x()), b.y()),
                                         Eigen::Vector2d(a.x(), a.y() + f * (b.y() - a.y())),
                                         Eigen::Vector2d(b.x(), a.y() + f * (b.y() - a.y()))}) {
          const Eigen::Vector3d p = item.X_CamBoard * Eigen::Vector3d(q.x(), q.y(), 0.0);
          if (p.z() <= 1e-6) behind = true; else all_behind = false;
          outline.push_back(p);
        }
      }
      if (all_behind) continue;
      if (!behind) {
        const auto px = camera_.project(outline);
        double mnx = 1e300, mny = 1e300, mxx = -1e300, mxy = -1e300;
        for (const auto& p : px) {
          mnx = std::min(mnx, p.x); mny = std::min(mny, p.y);
          mxx = std::max(mxx, p.x); mxy = std::max(mxy, p.y);
        }
        x0 = std::max(0, static_cast<int>(std::floor(mnx)) - 2);
        y0 = std::max(0, static_cast<int>(std::floor(mny)) - 2);
        x1 = std::min(W - 1, static_cast<int>(std::ceil(mxx)) + 2);
        y1 = std::min(H - 1, static_cast<int>(std::ceil(mxy)) + 2);
        if (x0 > x1 || y0 > y1) continue;
      }
    }

    // Board-plane coordinates at the pixel corners of the box.
    const int bw = x1 - x0 + 2, bh = y1 - y0 + 2;
    cv::Mat board_xy(bh, bw, CV_64FC2);
    cv::Mat board_z(bh, bw, CV_64F, cv::Scalar(std::numeric_limits<double>::infinity()));
    const double n_dot_o = n.dot(o);
    for (int j = 0; j < bh; ++j) {
      for (int i = 0; i < bw; ++i) {
        const cv::Vec2d r = rays_.at<cv::Vec2d>(y0 + j, x0 + i);
        const Eigen::Vector3d d(r[0], r[1], 1.0);
        const double denom = n.dot(d);
        const double t = std::abs(denom) > 1e-12 ? n_dot_o / denom : -1.0;
        if (t <= 0.0) {
          board_xy.at<cv::Vec2d>(j, i) = cv::Vec2d::all(std::numeric_limits<double>::quiet_NaN());
          continue;
        }
        const Eigen::Vector3d rel = t * d - o;
        board_xy.at<cv::Vec2d>(j, i) = cv::Vec2d(ex.dot(rel), ey.dot(rel));
        board_z.at<double>(j, i) = t;  // d.z = 1: t is the depth
      }
    }
    // Cells smaller than a few pixels could hide between corner samples: supersample all.
    const double depth = std::max(1.0, o.z());
    const bool supersample_all = min_cell_mm * camera_.K(0, 0) / depth < 3.0;

    std::vector<double> area(tags.size(), 0.0), occluded(tags.size(), 0.0);
    for (int j = 0; j + 1 < bh; ++j) {
      float* row = refl.ptr<float>(y0 + j);
      const std::uint8_t* mask_row = occ_mask.ptr<std::uint8_t>(y0 + j);
      for (int i = 0; i + 1 < bw; ++i) {
        const cv::Vec2d c00 = board_xy.at<cv::Vec2d>(j, i), c10 = board_xy.at<cv::Vec2d>(j, i + 1);
        const cv::Vec2d c01 = board_xy.at<cv::Vec2d>(j + 1, i), c11 = board_xy.at<cv::Vec2d>(j + 1, i + 1);
        const Region r00 = classify(c00[0], c00[1]);
        const bool uniform = !supersample_all && r00.id == classify(c10[0], c10[1]).id &&
                             r00.id == classify(c01[0], c01[1]).id && r00.id == classify(c11[0], c11[1]).id;
        float& px = row[x0 + i];
        if (!surface_z.empty()) {
          // A surface nearer than the board hides it (tag pixels then count as occluded).
          const double bz = std::min(std::min(board_z.at<double>(j, i), board_z.at<double>(j, i + 1)),
                                     std::min(board_z.at<double>(j + 1, i), board_z.at<double>(j + 1, i + 1)));
          if (static_cast<double>(surface_z.at<float>(y0 + j, x0 + i)) < bz) {
            if (r00.tag >= 0) {
              area[static_cast<size_t>(r00.tag)] += 1.0;
              occluded[static_cast<size_t>(r00.tag)] += 1.0;
            }
            continue;
          }
          if (r00.id >= 0 || !uniform) result.surface_mask.at<std::uint8_t>(y0 + j, x0 + i) = 0;
        }
        const bool masked = mask_row[x0 + i] != 0;
        if (uniform) {
          if (r00.id < 0) continue;
          px = r00.value;
          if (r00.tag >= 0) {
            area[static_cast<size_t>(r00.tag)] += 1.0;
            if (masked) occluded[static_cast<size_t>(r00.tag)] += 1.0;
          }
          continue;
        }
        double sum = 0.0;
        const double inv = 1.0 / (ss * ss);
        for (int sy = 0; sy < ss; ++sy) {
          const double fy = (sy + 0.5) / ss;
          for (int sx = 0; sx < ss; ++sx) {
            const double fx = (sx + 0.5) / ss;
            const cv::Vec2d top = c00 * (1 - fx) + c10 * fx, bottom = c01 * (1 - fx) + c11 * fx;
            const cv::Vec2d b = top * (1 - fy) + bottom * fy;
            const Region r = classify(b[0], b[1]);
            sum += r.id < 0 ? static_cast<double>(px) : static_cast<double>(r.value);
            if (r.tag >= 0) {
              area[static_cast<size_t>(r.tag)] += inv;
              if (masked) occluded[static_cast<size_t>(r.tag)] += inv;
            }
          }
        }
        px = static_cast<float>(sum * inv);
      }
    }

    for (size_t k = 0; k < board.tags.size(); ++k) {
      TagTruth truth;
      truth.board = board.name;
      truth.id = board.tags[k].id;
      truth.facing = facing;
      std::vector<Eigen::Vector3d> p_Cam;
      truth.in_front = true;
      for (const auto& p : markers::tag_corners_in_board(board.tags[k])) {
        p_Cam.push_back(item.X_CamBoard * p);
        truth.in_front = truth.in_front && p_Cam.back().z() > 1e-6;
      }
      if (truth.in_front) {
        const auto px = camera_.project(p_Cam);
        truth.in_image = true;
        for (int c = 0; c < 4; ++c) {
          truth.corners_px[static_cast<size_t>(c)] = px[static_cast<size_t>(c)];
          truth.in_image = truth.in_image && px[static_cast<size_t>(c)].x >= 0 && px[static_cast<size_t>(c)].y >= 0 &&
                           px[static_cast<size_t>(c)].x <= W - 1 && px[static_cast<size_t>(c)].y <= H - 1;
        }
      }
      truth.area_px = area[k];
      truth.occluded_fraction = area[k] > 0 ? occluded[k] / area[k] : 0.0;
      result.tags.push_back(truth);
    }
  }

  for (const auto& occ : options.occluders) {
    std::vector<cv::Point> poly;
    for (const auto& p : occ.polygon_px) poly.emplace_back(cvRound(p.x), cvRound(p.y));
    if (poly.size() >= 3) {
      cv::fillPoly(refl, std::vector<std::vector<cv::Point>>{poly}, cv::Scalar(occ.reflectance));
    }
  }

  // Light falling on the scene, then the optics (blur), then the sensor (gain, noise).
  const Lighting& L = options.lighting;
  const double cx = 0.5 * (W - 1), cy = 0.5 * (H - 1);
  const double r2_max = cx * cx + cy * cy;
  cv::Mat radiance(H, W, CV_32F);
  for (int v = 0; v < H; ++v) {
    const float* in = refl.ptr<float>(v);
    float* out = radiance.ptr<float>(v);
    for (int u = 0; u < W; ++u) {
      const double du = u - cx, dv = v - cy;
      double illum = 1.0 + L.gradient_per_px.x() * du + L.gradient_per_px.y() * dv;
      illum *= 1.0 - L.vignetting * (du * du + dv * dv) / r2_max;
      out[u] = static_cast<float>(255.0 * L.gain * std::max(0.0, illum) * static_cast<double>(in[u]) + L.offset);
    }
  }
  if (options.blur_sigma_px > 0.0) cv::GaussianBlur(radiance, radiance, cv::Size(0, 0), options.blur_sigma_px);
  result.image = expose_radiance(radiance, options);
  if (options.keep_radiance) result.radiance = radiance;
  return result;
}

cv::Mat expose_radiance(const cv::Mat& radiance, const RenderOptions& options) {
  cv::Mat image;
  if (options.noise_sigma > 0.0) {
    cv::Mat noise(radiance.rows, radiance.cols, CV_32F);
    cv::RNG rng(options.noise_seed);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, options.noise_sigma);
    noise += radiance;             // into the noise's own buffer: the radiance stays as it was
    noise.convertTo(image, CV_8U);  // rounds and saturates to 0..255
  } else {
    radiance.convertTo(image, CV_8U);
  }
  return image;
}

}  // namespace arnav::camera_sim
