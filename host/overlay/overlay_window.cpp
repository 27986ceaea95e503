#include "host/overlay/overlay_window.hpp"

#define GLFW_INCLUDE_ES3
#include <GLFW/glfw3.h>

#include "host/overlay/gl_program.hpp"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <mutex>

namespace arnav::host::overlay {
namespace {

// GLFW reports errors through a callback: the last one, for the exception's text.
std::mutex g_error_mutex;
std::string g_last_error;
void on_glfw_error(int code, const char* text) {
  std::lock_guard lock(g_error_mutex);
  char buf[32];
  std::snprintf(buf, sizeof buf, " (GLFW 0x%05x)", code);
  g_last_error = std::string(text ? text : "?") + buf;
}
std::string last_error() {
  std::lock_guard lock(g_error_mutex);
  return g_last_error.empty() ? std::string("no error text") : g_last_error;
}

// GLFW itself is initialised once per process and never terminated while a window may exist.
std::mutex g_init_mutex;
int g_windows = 0;

constexpr const char* kVertex = R"(#version 300 es
uniform vec2 scale;
out vec2 uv;
void main() {
  // Two triangles covering the letterboxed quad; uv (0,0) = the image's top-left pixel.
  const vec2 corners[6] = vec2[6](vec2(0, 0), vec2(1, 0), vec2(0, 1), vec2(1, 0), vec2(1, 1), vec2(0, 1));
  vec2 corner = corners[gl_VertexID];
  uv = vec2(corner.x, 1.0 - corner.y);
  gl_Position = vec4((corner * 2.0 - 1.0) * scale, 0.0, 1.0);
}
)";
// The texture holds OpenCV's BGR bytes uploaded as RGB: swap back.
constexpr const char* kFragment = R"(#version 300 es
precision mediump float;
uniform sampler2D image;
in vec2 uv;
out vec4 colour;
void main() { colour = vec4(texture(image, uv).bgr, 1.0); }
)";

}  // namespace

OverlayWindow::OverlayWindow(int width, int height, const std::string& title) {
  const char* x = std::getenv("DISPLAY");
  const char* wl = std::getenv("WAYLAND_DISPLAY");
  if ((!x || !*x) && (!wl || !*wl))
    throw DisplayError("no display to open a window on (DISPLAY and WAYLAND_DISPLAY are unset): run on the workstation's desktop, "
                       "with X forwarding (ssh -X), or under a virtual X server (xvfb-run), or remove 'display: {window: true}' "
                       "from the session (headless: the overlay is recorded with --record)");
  {
    std::lock_guard lock(g_init_mutex);
    glfwSetErrorCallback(on_glfw_error);
    if (g_windows == 0 && !glfwInit())
      throw DisplayError(std::string("cannot connect to the display '") + (x && *x ? x : wl) + "': " + last_error() +
                         ": check that the X/Wayland server runs and allows this user (xhost, XAUTHORITY), or remove "
                         "'display: {window: true}' from the session");
    ++g_windows;
  }
  const auto fail = [&](const std::string& what) {
    if (window_) glfwDestroyWindow(window_);
    window_ = nullptr;
    std::lock_guard lock(g_init_mutex);
    if (--g_windows == 0) glfwTerminate();
    throw DisplayError(what);
  };
  // OpenGL ES 3.0 through EGL like the renderer (a thread may switch between EGL contexts;
  // libglvnd refuses to mix a current GLX context with EGL ones), the native API second.
  for (int api : {GLFW_EGL_CONTEXT_API, GLFW_NATIVE_CONTEXT_API}) {
    glfwDefaultWindowHints();
    glfwWindowHint(GLFW_CLIENT_API, GLFW_OPENGL_ES_API);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 0);
    glfwWindowHint(GLFW_CONTEXT_CREATION_API, api);
    window_ = glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
    if (window_) {
      description_ = api == GLFW_EGL_CONTEXT_API ? "EGL window" : "native (GLX/Wayland) window";
      break;
    }
  }
  if (!window_)
    fail("cannot open an OpenGL ES 3.0 window on the display: " + last_error() +
         ": the display needs OpenGL (Mesa: libgl1-mesa-dri, libegl-mesa0; scripts/deps), or remove 'display: {window: true}' from the session");
  glfwMakeContextCurrent(window_);
  glfwSwapInterval(0);  // never wait for the monitor: the next camera frame must not be delayed
  std::string error;
  program_ = make_gl_program(kVertex, kFragment, error);
  if (!program_) fail("overlay window: " + error);
  u_scale_ = glGetUniformLocation(program_, "scale");
  glGenVertexArrays(1, &vao_);
  glGenTextures(1, &texture_);
  glBindTexture(GL_TEXTURE_2D, texture_);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  description_ = std::string(reinterpret_cast<const char*>(glGetString(GL_RENDERER))) + " | " +
                 reinterpret_cast<const char*>(glGetString(GL_VERSION)) + " | " + description_;
  if (glGetError() != GL_NO_ERROR) fail("overlay window: OpenGL error while setting up the window");
  glfwMakeContextCurrent(nullptr);  // the renderer's context is made current on this thread next
}

OverlayWindow::~OverlayWindow() {
  if (!window_) return;
  glfwMakeContextCurrent(window_);
  glDeleteTextures(1, &texture_);
  glDeleteVertexArrays(1, &vao_);
  glDeleteProgram(program_);
  glfwMakeContextCurrent(nullptr);
  glfwDestroyWindow(window_);
  std::lock_guard lock(g_init_mutex);
  if (--g_windows == 0) glfwTerminate();
}

void OverlayWindow::show(const cv::Mat& image) {
  if (image.type() != CV_8UC3 || image.empty()) throw DisplayError("overlay window: the frame must be a BGR image (CV_8UC3)");
  glfwMakeContextCurrent(window_);
  glBindTexture(GL_TEXTURE_2D, texture_);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, static_cast<GLint>(image.step / 3));
  if (image.cols != texture_width_ || image.rows != texture_height_) {
    // Storage once per frame size; every frame after that only replaces the texels.
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGB8, image.cols, image.rows, 0, GL_RGB, GL_UNSIGNED_BYTE, image.data);
    texture_width_ = image.cols;
    texture_height_ = image.rows;
  } else {
    glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, image.cols, image.rows, GL_RGB, GL_UNSIGNED_BYTE, image.data);
  }
  glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
  int fw = 0, fh = 0;
  glfwGetFramebufferSize(window_, &fw, &fh);
  glViewport(0, 0, fw, fh);
  glClearColor(0, 0, 0, 1);
  glClear(GL_COLOR_BUFFER_BIT);
  if (fw > 0 && fh > 0) {
    // Letterbox: the image's aspect kept inside the window.
    const double image_aspect = static_cast<double>(image.cols) / image.rows, window_aspect = static_cast<double>(fw) / fh;
    const float sx = image_aspect < window_aspect ? static_cast<float>(image_aspect / window_aspect) : 1.0f;
    const float sy = image_aspect > window_aspect ? static_cast<float>(window_aspect / image_aspect) : 1.0f;
    glUseProgram(program_);
    glUniform2f(u_scale_, sx, sy);
    glBindVertexArray(vao_);
    glDrawArrays(GL_TRIANGLES, 0, 6);
  }
  if (const GLenum e = glGetError(); e != GL_NO_ERROR) {
    char buf[80];
    std::snprintf(buf, sizeof buf, "overlay window: OpenGL error 0x%04x while drawing a frame", e);
    throw DisplayError(buf);
  }
  glfwSwapBuffers(window_);
  glfwMakeContextCurrent(nullptr);
  glfwPollEvents();
  ++frames_shown_;
}

bool OverlayWindow::close_requested() const { return window_ && glfwWindowShouldClose(window_); }

}  // namespace arnav::host::overlay
