#pragma once
// One top-level guard for every ARNav executable: whatever escapes the program's own error
// handling ends as a one-line message naming the program and exit code 3, never as
// std::terminate and a core dump. Exit codes of all executables (docs/architecture.md):
//   0 done, 1 ran but did not succeed (not converged, unhealthy, a failed check),
//   2 bad input or usage (the message names the file, line, port or option and the fix),
//   3 internal error (a bug: the message asks for a report with the command line).
#include <exception>
#include <iostream>
#include <new>
#include <string>

namespace arnav {

inline constexpr int kExitInternalError = 3;

template <class Body>
int guarded_main(const char* program, Body&& body) noexcept {
  try {
    return body();
  } catch (const std::bad_alloc&) {
    std::cerr << program << ": out of memory: close other programs or use a smaller input\n";
  } catch (const std::exception& e) {
    std::cerr << program << ": internal error: " << e.what()
              << " (this is a bug: please report it with the command line and input files)\n";
  } catch (...) {
    std::cerr << program << ": internal error: unknown exception (this is a bug: please report it with the command line)\n";
  }
  return kExitInternalError;
}

}  // namespace arnav
