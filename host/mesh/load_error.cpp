#include "host/mesh/load_error.hpp"

namespace arnav::host {

void throw_load_error(const std::string& source, int line, const std::string& what, const std::string& fix) {
  std::string message;
  message.reserve(source.size() + what.size() + fix.size() + 32);
  message.append(source);
  if (line > 0) message.append(":").append(std::to_string(line));
  message.append(": ").append(what);
  if (!fix.empty()) message.append(". Fix: ").append(fix);
  throw LoadError(message);
}

}  // namespace arnav::host
