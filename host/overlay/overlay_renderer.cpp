#include "host/overlay/overlay_renderer.hpp"

#include <GLES3/gl3.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include <opencv2/imgproc.hpp>

#include "host/overlay/egl_context.hpp"
#include "host/overlay/gl_program.hpp"
#include "host/overlay/overlay_geometry.hpp"

namespace arnav::host::overlay {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

constexpr const char* kVertexShader = R"(#version 300 es
layout(location = 0) in vec3 p_Cam;
layout(location = 1) in vec3 n_Cam;
uniform mat4 projection;
out vec3 v_p;
out vec3 v_n;
void main() {
  v_p = p_Cam;
  v_n = n_Cam;
  gl_Position = projection * vec4(p_Cam, 1.0);
}
)";

// mode 0: flat colour; 1: lit (headlight); 2: organ veil (alpha rises toward the outline).
// Output is BGRA with premultiplied alpha, so the read-back bytes are OpenCV's order.
constexpr const char* kFragmentShader = R"(#version 300 es
precision highp float;
in vec3 v_p;
in vec3 v_n;
uniform vec4 colour;
uniform int mode;
out vec4 out_bgra;
void main() {
  vec4 c = colour;
  if (mode != 0) {
    float facing = abs(dot(normalize(v_n), normalize(-v_p)));
    if (mode == 1) c.rgb *= 0.35 + 0.65 * facing;
    else c.a = clamp(c.a + (1.0 - c.a) * 0.7 * pow(1.0 - facing, 3.0), 0.0, 1.0);
  }
  out_bgra = vec4(c.b * c.a, c.g * c.a, c.r * c.a, c.a);
}
)";

void check_gl(const char* step) {
  const GLenum e = glGetError();
  if (e != GL_NO_ERROR) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "0x%04x", e);
    throw OverlayError(std::string("OpenGL error ") + buf + " in " + step);
  }
}

}  // namespace

struct OverlayRenderer::Impl {
  EglContext context;
  OverlayCamera camera;
  OverlayStyle style;
  DistortionWarp warp;
  Eigen::Matrix4f projection;
  GLuint program = 0, vao = 0, vbo = 0, ebo = 0;
  GLint u_projection = -1, u_colour = -1, u_mode = -1;
  GLuint draw_fbo = 0, draw_colour = 0, draw_depth = 0;     // multisampled when msaa > 0
  GLuint resolve_fbo = 0, resolve_colour = 0;
  int samples = 0;
  std::vector<float> vertex_data;
  // Edge adjacency of the organ surface, rebuilt when the topology changes (a cut).
  std::vector<std::array<int, 3>> adjacency_tris;
  std::vector<EdgeFaces> adjacency;
  cv::Mat canvas;
  cv::Rect canvas_roi;             // the canvas part read back last frame (the rest is zero)
  // The lens warp by tiles of the output image: the canvas rectangle each tile samples
  // (bilinear neighbours included; empty where it samples nothing), so a frame warps only
  // the output tiles that can see what was drawn.
  static constexpr int kTile = 16;
  int tiles_x = 0, tiles_y = 0;
  std::vector<cv::Rect> tile_source;

  Impl(const OverlayCamera& cam, const OverlayStyle& st) : camera(cam), style(st) {
    validate(camera);
    warp = DistortionWarp::make(camera);
    projection = gl_projection(camera.K, warp.canvas_width, warp.canvas_height, warp.offset_px, style.near_mm, style.far_mm);
    std::string error;
    program = make_gl_program(kVertexShader, kFragmentShader, error);
    if (!program) throw OverlayError("overlay renderer: " + error);
    u_projection = glGetUniformLocation(program, "projection");
    u_colour = glGetUniformLocation(program, "colour");
    u_mode = glGetUniformLocation(program, "mode");
    glGenVertexArrays(1, &vao);
    glGenBuffers(1, &vbo);
    glGenBuffers(1, &ebo);
    glBindVertexArray(vao);
    glBindBuffer(GL_ARRAY_BUFFER, vbo);
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, ebo);
    glEnableVertexAttribArray(0);
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 6 * sizeof(float), nullptr);
    glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, 6 * sizeof(float), reinterpret_cast<void*>(3 * sizeof(float)));

    GLint max_samples = 0;
    glGetIntegerv(GL_MAX_SAMPLES, &max_samples);
    samples = std::clamp(style.msaa_samples, 0, max_samples);
    const int w = warp.canvas_width, h = warp.canvas_height;
    glGenFramebuffers(1, &resolve_fbo);
    glGenRenderbuffers(1, &resolve_colour);
    glBindRenderbuffer(GL_RENDERBUFFER, resolve_colour);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, w, h);
    glBindFramebuffer(GL_FRAMEBUFFER, resolve_fbo);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, resolve_colour);
    if (samples > 0) {
      glGenFramebuffers(1, &draw_fbo);
      glGenRenderbuffers(1, &draw_colour);
      glBindRenderbuffer(GL_RENDERBUFFER, draw_colour);
      glRenderbufferStorageMultisample(GL_RENDERBUFFER, samples, GL_RGBA8, w, h);
      glBindFramebuffer(GL_FRAMEBUFFER, draw_fbo);
      glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, draw_colour);
    } else {
      draw_fbo = resolve_fbo;
    }
    glGenRenderbuffers(1, &draw_depth);
    glBindRenderbuffer(GL_RENDERBUFFER, draw_depth);
    if (samples > 0)
      glRenderbufferStorageMultisample(GL_RENDERBUFFER, samples, GL_DEPTH_COMPONENT24, w, h);
    else
      glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, w, h);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, draw_depth);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
      throw OverlayError("overlay framebuffer " + std::to_string(w) + "x" + std::to_string(h) + " is incomplete (too large for the driver?)");
    canvas = cv::Mat::zeros(h, w, CV_8UC4);
    if (!warp.identity) {
      tiles_x = (camera.width + kTile - 1) / kTile;
      tiles_y = (camera.height + kTile - 1) / kTile;
      tile_source.assign(static_cast<std::size_t>(tiles_x) * tiles_y, cv::Rect());
      for (int ty = 0; ty < tiles_y; ++ty)
        for (int tx = 0; tx < tiles_x; ++tx) {
          int x0 = w, y0 = h, x1 = -1, y1 = -1;
          for (int v = ty * kTile; v < std::min(camera.height, (ty + 1) * kTile); ++v) {
            const auto* m = warp.map1.ptr<cv::Vec2s>(v);
            for (int u = tx * kTile; u < std::min(camera.width, (tx + 1) * kTile); ++u) {
              const int x = m[u][0], y = m[u][1];  // bilinear: (x, y) .. (x + 1, y + 1)
              if (x + 1 < 0 || y + 1 < 0 || x >= w || y >= h) continue;
              x0 = std::min(x0, std::max(x, 0));
              y0 = std::min(y0, std::max(y, 0));
              x1 = std::max(x1, std::min(x + 1, w - 1));
              y1 = std::max(y1, std::min(y + 1, h - 1));
            }
          }
          if (x1 >= x0 && y1 >= y0) tile_source[static_cast<std::size_t>(ty) * tiles_x + tx] = cv::Rect(x0, y0, x1 - x0 + 1, y1 - y0 + 1);
        }
    }
    check_gl("overlay set-up");
  }

  // Canvas pixels that the geometry can cover: the projected vertices' bounding box, padded
  // by pad_mm at each vertex's depth (tube radii) and by the line width. A vertex at or
  // behind the near plane covers the whole canvas.
  struct Bounds {
    double x0 = 1e300, y0 = 1e300, x1 = -1e300, y1 = -1e300;
    bool everything = false;
  };
  void extend(Bounds& b, const Eigen::Matrix3Xd& p_Cam, double pad_mm) const {
    const cv::Matx33d& K = camera.K;
    for (Eigen::Index i = 0; i < p_Cam.cols(); ++i) {
      const double z = p_Cam(2, i);
      if (!(z > style.near_mm)) {
        b.everything = true;
        return;
      }
      const double x = p_Cam(0, i) / z, y = p_Cam(1, i) / z;
      const double u = K(0, 0) * x + K(0, 1) * y + K(0, 2) + warp.offset_px.x, v = K(1, 1) * y + K(1, 2) + warp.offset_px.y;
      const double r = pad_mm * std::max(K(0, 0), K(1, 1)) / z;
      b.x0 = std::min(b.x0, u - r);
      b.y0 = std::min(b.y0, v - r);
      b.x1 = std::max(b.x1, u + r);
      b.y1 = std::max(b.y1, v + r);
    }
  }
  cv::Rect to_rect(const Bounds& b) const {
    const cv::Rect all(0, 0, warp.canvas_width, warp.canvas_height);
    if (b.everything) return all;
    if (b.x1 < b.x0) return {};
    const double pad = 2.0 + 2.0 * static_cast<double>(style.line_width_px);  // pixel centres, rasterisation rules, thick lines
    const double x0 = std::max(-1.0, std::floor(b.x0 - pad)), y0 = std::max(-1.0, std::floor(b.y0 - pad));
    const double x1 = std::min(static_cast<double>(all.width), std::ceil(b.x1 + pad));
    const double y1 = std::min(static_cast<double>(all.height), std::ceil(b.y1 + pad));
    if (x1 <= x0 || y1 <= y0) return {};
    return cv::Rect(static_cast<int>(x0), static_cast<int>(y0), static_cast<int>(x1 - x0), static_cast<int>(y1 - y0)) & all;
  }
  // Output pixels whose warp samples the canvas rectangle `r`.
  cv::Rect output_roi(const cv::Rect& r) const {
    if (r.area() == 0) return {};
    if (warp.identity) return r;
    int x0 = camera.width, y0 = camera.height, x1 = 0, y1 = 0;
    for (int ty = 0; ty < tiles_y; ++ty)
      for (int tx = 0; tx < tiles_x; ++tx) {
        const cv::Rect& s = tile_source[static_cast<std::size_t>(ty) * tiles_x + tx];
        if ((s & r).area() == 0) continue;
        x0 = std::min(x0, tx * kTile);
        y0 = std::min(y0, ty * kTile);
        x1 = std::max(x1, std::min(camera.width, (tx + 1) * kTile));
        y1 = std::max(y1, std::min(camera.height, (ty + 1) * kTile));
      }
    return x1 > x0 && y1 > y0 ? cv::Rect(x0, y0, x1 - x0, y1 - y0) : cv::Rect();
  }

  ~Impl() {
    glDeleteFramebuffers(1, &resolve_fbo);
    if (samples > 0) {
      glDeleteFramebuffers(1, &draw_fbo);
      glDeleteRenderbuffers(1, &draw_colour);
    }
    glDeleteRenderbuffers(1, &resolve_colour);
    glDeleteRenderbuffers(1, &draw_depth);
    glDeleteBuffers(1, &vbo);
    glDeleteBuffers(1, &ebo);
    glDeleteVertexArrays(1, &vao);
    glDeleteProgram(program);
  }

  void upload(const Eigen::Matrix3Xd& p_Cam, const Eigen::Matrix3Xd* n_Cam, const std::vector<unsigned>& indices) {
    vertex_data.resize(static_cast<std::size_t>(p_Cam.cols()) * 6);
    for (Eigen::Index i = 0; i < p_Cam.cols(); ++i) {
      float* v = &vertex_data[static_cast<std::size_t>(i) * 6];
      for (int k = 0; k < 3; ++k) {
        v[k] = static_cast<float>(p_Cam(k, i));
        v[3 + k] = n_Cam ? static_cast<float>((*n_Cam)(k, i)) : 0.0f;
      }
    }
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(vertex_data.size() * sizeof(float)), vertex_data.data(), GL_STREAM_DRAW);
    glBufferData(GL_ELEMENT_ARRAY_BUFFER, static_cast<GLsizeiptr>(indices.size() * sizeof(unsigned)), indices.data(), GL_STREAM_DRAW);
  }

  void set_colour(const Rgba& c, int mode) {
    glUniform4f(u_colour, c.r, c.g, c.b, c.a);
    glUniform1i(u_mode, mode);
  }

  void draw_mesh(const Eigen::Matrix3Xd& p_Cam, const std::vector<std::array<int, 3>>& tris, const Rgba& colour, int mode) {
    if (tris.empty()) return;
    const Eigen::Matrix3Xd n = vertex_normals(p_Cam, tris);
    std::vector<unsigned> idx;
    idx.reserve(tris.size() * 3);
    for (const auto& t : tris)
      for (int k : t) idx.push_back(static_cast<unsigned>(k));
    upload(p_Cam, &n, idx);
    set_colour(colour, mode);
    glDrawElements(GL_TRIANGLES, static_cast<GLsizei>(idx.size()), GL_UNSIGNED_INT, nullptr);
  }

  void draw_lines(const Eigen::Matrix3Xd& p_Cam, const std::vector<unsigned>& idx, const Rgba& colour) {
    if (idx.empty()) return;
    upload(p_Cam, nullptr, idx);
    set_colour(colour, 0);
    glDrawElements(GL_LINES, static_cast<GLsizei>(idx.size()), GL_UNSIGNED_INT, nullptr);
  }

  cv::Mat render(const OverlayContent& c, RenderTiming* timing) {
    const auto t0 = Clock::now();
    context.make_current();
    const auto to_cam = [&](const Eigen::Matrix3Xd& p_Model) -> Eigen::Matrix3Xd { return c.X_CamModel * p_Model; };
    const unsigned L = c.layers;
    double geometry_ms = 0;
    const auto geo = [&](auto&& f) {
      const auto g0 = Clock::now();
      f();
      geometry_ms += ms_since(g0);
    };

    // What this frame can cover on the canvas: clear, draw and read back only that.
    cv::Rect roi;
    geo([&] {
      Bounds b;
      const auto add = [&](const TriMesh* m, double pad_mm) {
        if (m && !b.everything) extend(b, to_cam(m->positions_World_mm), pad_mm);
      };
      if (L & kTumour)
        for (const TriMesh* m : c.tumours) add(m, 0.0);
      if (L & kMargin)
        for (const TriMesh* m : c.margins) add(m, 0.0);
      if ((L & kVessels) && c.vessels && !c.vessels->segments.empty() && !b.everything) {
        const double r = c.vessels->radius_mm.empty() ? 0.0 : *std::max_element(c.vessels->radius_mm.begin(), c.vessels->radius_mm.end());
        extend(b, to_cam(c.vessels->nodes_World_mm), r);
      }
      if (L & kCut) {
        add(c.cut_surface, 0.0);
        for (const auto& path : c.cut_paths_mm)
          for (const auto& p : path)
            if (!b.everything) extend(b, c.X_CamModel * p, 0.0);
      }
      if (L & (kOrganVeil | kOutline)) add(c.organ, 0.0);
      if (c.scalpel_mm && (L & kScalpel) && !b.everything) {
        Eigen::Matrix3Xd ends(3, 2);
        ends.col(0) = c.X_CamModel * (*c.scalpel_mm)[0];
        ends.col(1) = c.X_CamModel * (*c.scalpel_mm)[1];
        extend(b, ends, style.scalpel_radius_mm * 1.1);  // the 8-sided tube's corners
      }
      roi = to_rect(b);
    });

    glBindFramebuffer(GL_FRAMEBUFFER, draw_fbo);
    glViewport(0, 0, warp.canvas_width, warp.canvas_height);
    glEnable(GL_SCISSOR_TEST);
    glScissor(roi.x, roi.y, roi.width, roi.height);  // canvas rows = window rows (no flip)
    glClearColor(0, 0, 0, 0);
    glClearDepthf(1.0f);
    glDepthMask(GL_TRUE);
    glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    glUseProgram(program);
    glUniformMatrix4fv(u_projection, 1, GL_FALSE, projection.data());
    glBindVertexArray(vao);
    glEnable(GL_BLEND);
    glBlendFunc(GL_ONE, GL_ONE_MINUS_SRC_ALPHA);  // premultiplied
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LESS);
    glFrontFace(GL_CW);  // outward faces turned to the camera are clockwise in window coordinates (no y flip)
    glDisable(GL_CULL_FACE);
    glLineWidth(style.line_width_px);

    // 1. Inside structures, depth-tested among themselves.
    if (L & kTumour)
      for (const TriMesh* m : c.tumours)
        if (m) draw_mesh(to_cam(m->positions_World_mm), m->tris, style.tumour, 1);
    if ((L & kVessels) && c.vessels && !c.vessels->segments.empty()) {
      TriMesh tube;
      geo([&] { tube = tubes(to_cam(c.vessels->nodes_World_mm), c.vessels->radius_mm, c.vessels->segments); });
      draw_mesh(tube.positions_World_mm, tube.tris, style.vessels, 1);
    }
    if (L & kCut) {
      if (c.cut_surface) draw_mesh(to_cam(c.cut_surface->positions_World_mm), c.cut_surface->tris, style.cut, 1);
      std::size_t n = 0;
      for (const auto& path : c.cut_paths_mm) n += path.size();
      if (n >= 2) {
        Eigen::Matrix3Xd p(3, static_cast<Eigen::Index>(n));
        std::vector<unsigned> idx;
        unsigned i = 0;
        for (const auto& path : c.cut_paths_mm)
          for (std::size_t k = 0; k < path.size(); ++k, ++i) {
            p.col(i) = c.X_CamModel * path[k];
            if (k + 1 < path.size()) {
              idx.push_back(i);
              idx.push_back(i + 1);
            }
          }
        glLineWidth(2.0f * style.line_width_px);
        draw_lines(p, idx, style.cut);
        glLineWidth(style.line_width_px);
      }
    }
    if (L & kMargin) {
      glDepthMask(GL_FALSE);
      glEnable(GL_CULL_FACE);
      glCullFace(GL_BACK);
      for (const TriMesh* m : c.margins)
        if (m) draw_mesh(to_cam(m->positions_World_mm), m->tris, style.margin, 1);
      glDisable(GL_CULL_FACE);
      glDepthMask(GL_TRUE);
    }
    // 2. The organ's front surface as a veil over them; 3. its outline on top.
    Eigen::Matrix3Xd organ_Cam;
    if (c.organ) geo([&] { organ_Cam = to_cam(c.organ->positions_World_mm); });
    // The veil writes the front surface's depth: the scalpel pass tests against it.
    bool organ_depth_written = false;
    if (c.organ && (L & kOrganVeil)) {
      glEnable(GL_CULL_FACE);
      glCullFace(GL_BACK);
      draw_mesh(organ_Cam, c.organ->tris, style.organ_veil, 2);
      glDisable(GL_CULL_FACE);
      organ_depth_written = true;
    }
    if (c.organ && (L & kOutline)) {
      std::vector<unsigned> idx;
      geo([&] {
        if (adjacency_tris != c.organ->tris) {
          adjacency = edge_faces(c.organ->tris);
          adjacency_tris = c.organ->tris;
        }
        for (const auto& e : silhouette_edges(organ_Cam, c.organ->tris, adjacency, Eigen::Vector3d::Zero())) {
          idx.push_back(static_cast<unsigned>(e[0]));
          idx.push_back(static_cast<unsigned>(e[1]));
        }
      });
      glDisable(GL_DEPTH_TEST);
      draw_lines(organ_Cam, idx, style.outline);
      glEnable(GL_DEPTH_TEST);
    }
    // 4. The scalpel against the organ surface's depth: solid in front, dimmed inside.
    if (c.scalpel_mm && (L & kScalpel)) {
      if (!organ_depth_written) glClear(GL_DEPTH_BUFFER_BIT);
      if (c.organ && !organ_depth_written) {
        glColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
        draw_mesh(organ_Cam, c.organ->tris, style.organ_veil, 0);
        glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
      }
      Eigen::Matrix3Xd ends(3, 2);
      ends.col(0) = c.X_CamModel * (*c.scalpel_mm)[0];
      ends.col(1) = c.X_CamModel * (*c.scalpel_mm)[1];
      const TriMesh blade = tubes(ends, {style.scalpel_radius_mm, style.scalpel_radius_mm}, {{0, 1}});
      draw_mesh(blade.positions_World_mm, blade.tris, style.scalpel, 1);
      glDepthMask(GL_FALSE);
      glDepthFunc(GL_GREATER);
      Rgba inside = style.scalpel;
      inside.a *= style.scalpel_inside_alpha;
      draw_mesh(blade.positions_World_mm, blade.tris, inside, 1);
      glDepthFunc(GL_LESS);
      glDepthMask(GL_TRUE);
    }
    if (samples > 0 && roi.area() > 0) {
      glBindFramebuffer(GL_READ_FRAMEBUFFER, draw_fbo);
      glBindFramebuffer(GL_DRAW_FRAMEBUFFER, resolve_fbo);
      glBlitFramebuffer(roi.x, roi.y, roi.br().x, roi.br().y, roi.x, roi.y, roi.br().x, roi.br().y, GL_COLOR_BUFFER_BIT, GL_NEAREST);
    }
    glDisable(GL_SCISSOR_TEST);
    // The canvas outside roi must read as transparent: clear what the last frame left there.
    if (canvas_roi.area() > 0) canvas(canvas_roi).setTo(cv::Scalar::all(0));
    canvas_roi = roi;
    if (roi.area() > 0) {
      glBindFramebuffer(GL_READ_FRAMEBUFFER, resolve_fbo);
      glPixelStorei(GL_PACK_ALIGNMENT, 4);
      glPixelStorei(GL_PACK_ROW_LENGTH, canvas.cols);
      glReadPixels(roi.x, roi.y, roi.width, roi.height, GL_RGBA, GL_UNSIGNED_BYTE, canvas.ptr<std::uint8_t>(roi.y) + 4 * roi.x);
      glPixelStorei(GL_PACK_ROW_LENGTH, 0);
    } else {
      glFinish();
    }
    check_gl("overlay render");
    const double gl_total = ms_since(t0);
    const auto w0 = Clock::now();
    const cv::Rect out_roi = output_roi(roi);
    cv::Mat out(camera.height, camera.width, CV_8UC4, cv::Scalar::all(0));
    if (out_roi.area() > 0) {
      cv::Mat dst = out(out_roi);
      if (warp.identity)
        canvas(out_roi).copyTo(dst);
      else
        cv::remap(canvas, dst, warp.map1(out_roi), warp.map2(out_roi), cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar::all(0));
    }
    if (timing) {
      timing->geometry_ms = geometry_ms;
      timing->gl_ms = gl_total - geometry_ms;
      timing->warp_ms = ms_since(w0);
      timing->total_ms = ms_since(t0);
      timing->drawn_px = out_roi;
    }
    return out;
  }
};

OverlayRenderer::OverlayRenderer(const OverlayCamera& camera, const OverlayStyle& style) : impl_(std::make_unique<Impl>(camera, style)) {}
OverlayRenderer::~OverlayRenderer() = default;
const OverlayCamera& OverlayRenderer::camera() const { return impl_->camera; }
std::string OverlayRenderer::gl_description() const { return impl_->context.description(); }
cv::Mat OverlayRenderer::render(const OverlayContent& content, RenderTiming* timing) { return impl_->render(content, timing); }

void composite(cv::Mat& image_bgr, const cv::Mat& overlay, const cv::Rect& roi) {
  if (image_bgr.size() != overlay.size())
    throw OverlayError("composite: the camera image (" + std::to_string(image_bgr.cols) + "x" + std::to_string(image_bgr.rows) +
                       ") and the overlay (" + std::to_string(overlay.cols) + "x" + std::to_string(overlay.rows) + ") must have the same size");
  const cv::Rect r = roi & cv::Rect(0, 0, image_bgr.cols, image_bgr.rows);
  if (r.area() == 0) return;
  cv::Mat dst = image_bgr(r);
  composite(dst, overlay(r));
}

void composite(cv::Mat& image_bgr, const cv::Mat& overlay) {
  if (image_bgr.type() != CV_8UC3 || overlay.type() != CV_8UC4 || image_bgr.size() != overlay.size())
    throw OverlayError("composite: the camera image (" + std::to_string(image_bgr.cols) + "x" + std::to_string(image_bgr.rows) +
                       ") and the overlay (" + std::to_string(overlay.cols) + "x" + std::to_string(overlay.rows) +
                       ") must have the same size, BGR and BGRA");
  cv::parallel_for_(cv::Range(0, image_bgr.rows), [&](const cv::Range& rows) {
    for (int v = rows.start; v < rows.end; ++v) {
      auto* dst = image_bgr.ptr<std::uint8_t>(v);
      const auto* src = overlay.ptr<std::uint8_t>(v);
      for (int u = 0; u < image_bgr.cols; ++u, dst += 3, src += 4) {
        const unsigned a = src[3];
        if (a == 0) continue;
        const unsigned keep = 255 - a;
        for (int k = 0; k < 3; ++k) dst[k] = static_cast<std::uint8_t>(std::min(255u, src[k] + (dst[k] * keep + 127) / 255));
      }
    }
  });
}

void draw_status(cv::Mat& image, const std::vector<Banner>& banners, std::optional<double> blade_to_margin_mm, double warn_mm,
                 const std::string& footer) {
  const double scale = std::max(0.5, image.rows / 720.0);
  const int font = cv::FONT_HERSHEY_SIMPLEX;
  const int bar = static_cast<int>(std::lround(34 * scale));
  int y = 0;
  for (const auto& b : banners) {
    cv::rectangle(image, {0, y, image.cols, bar}, b.colour_bgr, cv::FILLED);
    cv::putText(image, b.text, {static_cast<int>(12 * scale), y + static_cast<int>(25 * scale)}, font, 0.8 * scale,
                cv::Scalar(255, 255, 255), std::max(1, static_cast<int>(2 * scale)), cv::LINE_AA);
    y += bar + 2;
  }
  if (blade_to_margin_mm) {
    const double d = *blade_to_margin_mm;
    const cv::Scalar colour = d < 0 ? cv::Scalar(0, 0, 255) : d < warn_mm ? cv::Scalar(0, 190, 255) : cv::Scalar(0, 210, 0);
    char text[64];
    std::snprintf(text, sizeof text, "margin %+.1f mm", d);
    int base = 0;
    const cv::Size size = cv::getTextSize(text, font, 1.1 * scale, static_cast<int>(3 * scale), &base);
    const cv::Point origin(static_cast<int>(12 * scale), image.rows - static_cast<int>(40 * scale));
    cv::rectangle(image, {origin.x - 6, origin.y - size.height - 8, size.width + 12, size.height + base + 14}, cv::Scalar(0, 0, 0), cv::FILLED);
    cv::putText(image, text, origin, font, 1.1 * scale, colour, std::max(1, static_cast<int>(3 * scale)), cv::LINE_AA);
  }
  if (!footer.empty())
    cv::putText(image, footer, {static_cast<int>(12 * scale), image.rows - static_cast<int>(12 * scale)}, font, 0.5 * scale,
                cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
}

}  // namespace arnav::host::overlay
