#pragma once
// One OpenGL ES 3 shader program from a vertex and a fragment shader source, for the
// offscreen renderer (EGL) and the display window (GLFW): the context must be current.
#include <string>

namespace arnav::host::overlay {

// Returns the program's name, or 0 with `error` saying which shader did not compile or that
// the program did not link, with the driver's log.
unsigned make_gl_program(const char* vertex_source, const char* fragment_source, std::string& error);

}  // namespace arnav::host::overlay
