#pragma once
// Errors of scene and mesh loading. Every message names the input (file and line, byte
// offset or element) and says how to fix it, so a user can act on it without a debugger.
#include <stdexcept>
#include <string>

namespace arnav::host {

class LoadError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// "<source>:<line>: <what>. Fix: <fix>" (line omitted when 0).
[[noreturn]] void throw_load_error(const std::string& source, int line, const std::string& what, const std::string& fix);

}  // namespace arnav::host
