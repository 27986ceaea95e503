#pragma once
// Error type of the calibration library. Messages name the input (file, line, key) and
// say what to do; callers (arnav-calib, the appliance) print them verbatim.
#include <filesystem>
#include <stdexcept>
#include <string>

namespace arnav::calib {

class CalibError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Rejected because the data cannot determine the answer (rank deficiency, too little
// motion, too few views). Separate type so tools can exit with a distinct message.
class DegenerateInput : public CalibError {
 public:
  using CalibError::CalibError;
};

// Whole file as text; throws CalibError "PATH: cannot open <what> (...)" when unreadable.
std::string read_text_file(const std::filesystem::path& path, const std::string& what);

// "2026-11-21T10:07:55Z": the date stamped into every calibration file.
std::string utc_now_iso8601();

}  // namespace arnav::calib
