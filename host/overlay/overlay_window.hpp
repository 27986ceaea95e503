#pragma once
// A workstation window showing the finished overlay frames (GLFW, OpenGL ES 3): the
// display of a live session when the session file says `display: {window: true}`; the
// recording and the headless EGL renderer stay as they are (tests and CI run without one).
// The frame (BGR, the camera's size) goes into one persistent texture (glTexSubImage2D per
// frame) drawn as a full-window quad, aspect kept; buffers are swapped without waiting
// for the monitor's refresh (swap interval 0) so showing a frame never delays the next.
// Create, use and destroy it on one thread (the session's rendering thread).
#include <opencv2/core.hpp>

#include <memory>
#include <stdexcept>
#include <string>

struct GLFWwindow;

namespace arnav::host::overlay {

// No display to open a window on (no DISPLAY / WAYLAND_DISPLAY, the server refused, no
// OpenGL ES context for it). The text says which and what to do.
class DisplayError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class OverlayWindow {
 public:
  // Opens a width x height window (resizable). Throws DisplayError.
  OverlayWindow(int width, int height, const std::string& title);
  ~OverlayWindow();
  OverlayWindow(const OverlayWindow&) = delete;
  OverlayWindow& operator=(const OverlayWindow&) = delete;

  // Shows a CV_8UC3 BGR frame (any size: scaled to the window, aspect kept) and handles the
  // window's events. Throws DisplayError on a GL error.
  void show(const cv::Mat& image_bgr);
  // The user closed the window (its close button / Alt-F4).
  bool close_requested() const;
  std::int64_t frames_shown() const { return frames_shown_; }
  // "llvmpipe (...) | OpenGL ES 3.2 Mesa ..." of the window's context, and how it was made (GLX/EGL).
  const std::string& description() const { return description_; }
  GLFWwindow* handle() const { return window_; }

 private:
  GLFWwindow* window_ = nullptr;
  unsigned program_ = 0, vao_ = 0, texture_ = 0;
  int texture_width_ = 0, texture_height_ = 0;
  int u_scale_ = -1;
  std::int64_t frames_shown_ = 0;
  std::string description_;
};

}  // namespace arnav::host::overlay
