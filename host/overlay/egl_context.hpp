#pragma once
// A headless OpenGL ES 3 context through EGL: Mesa's surfaceless platform
// (EGL_MESA_platform_surfaceless), rendering into framebuffer objects only. On machines
// without a GPU Mesa picks its software rasteriser (llvmpipe); with one, its driver. The
// context is current on the thread that created it: create and use it on one thread.
#include <stdexcept>
#include <string>

namespace arnav::host::overlay {

class OverlayError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class EglContext {
 public:
  // Throws OverlayError saying which EGL step failed and what to install/check.
  EglContext();
  ~EglContext();
  EglContext(const EglContext&) = delete;
  EglContext& operator=(const EglContext&) = delete;

  void make_current() const;
  // "llvmpipe (LLVM 15.0.6, 256 bits) | OpenGL ES 3.2 Mesa 22.3.6"
  const std::string& description() const { return description_; }

 private:
  void* display_ = nullptr;
  void* context_ = nullptr;
  std::string description_;
};

}  // namespace arnav::host::overlay
