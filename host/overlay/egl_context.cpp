#include "host/overlay/egl_context.hpp"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GLES3/gl3.h>

#include <sstream>

namespace arnav::host::overlay {
namespace {

std::string egl_error_text(const char* step) {
  std::ostringstream os;
  os << "EGL: " << step << " failed (error 0x" << std::hex << eglGetError() << std::dec
     << "): the overlay needs Mesa's EGL (Debian: libegl-mesa0 libgl1-mesa-dri, see scripts/deps)";
  return os.str();
}

}  // namespace

EglContext::EglContext() {
  auto get_platform_display =
      reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
  EGLDisplay display = EGL_NO_DISPLAY;
  if (get_platform_display) display = get_platform_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
  if (display == EGL_NO_DISPLAY) throw OverlayError(egl_error_text("opening the surfaceless display (EGL_MESA_platform_surfaceless)"));
  EGLint major = 0, minor = 0;
  if (!eglInitialize(display, &major, &minor)) throw OverlayError(egl_error_text("eglInitialize"));
  if (!eglBindAPI(EGL_OPENGL_ES_API)) {
    eglTerminate(display);
    throw OverlayError(egl_error_text("eglBindAPI(OpenGL ES)"));
  }
  const EGLint config_attribs[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_ES3_BIT, EGL_NONE};
  EGLConfig config = nullptr;
  EGLint count = 0;
  eglChooseConfig(display, config_attribs, &config, 1, &count);
  const EGLint context_attribs[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 0, EGL_NONE};
  // Framebuffer objects only: a config-less context is enough where the driver offers one.
  EGLContext context = eglCreateContext(display, count > 0 ? config : EGL_NO_CONFIG_KHR, EGL_NO_CONTEXT, context_attribs);
  if (context == EGL_NO_CONTEXT) {
    const std::string what = egl_error_text("creating an OpenGL ES 3.0 context");
    eglTerminate(display);
    throw OverlayError(what);
  }
  display_ = display;
  context_ = context;
  make_current();
  std::ostringstream os;
  os << reinterpret_cast<const char*>(glGetString(GL_RENDERER)) << " | " << reinterpret_cast<const char*>(glGetString(GL_VERSION));
  description_ = os.str();
}

EglContext::~EglContext() {
  if (display_) {
    eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    if (context_) eglDestroyContext(display_, context_);
    eglTerminate(display_);
  }
}

void EglContext::make_current() const {
  if (!eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, context_))
    throw OverlayError(egl_error_text("eglMakeCurrent (surfaceless)"));
}

}  // namespace arnav::host::overlay
