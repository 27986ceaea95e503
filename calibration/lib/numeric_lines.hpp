#pragma once
// Text files of numbers, one record per line (the calibration tools' pose, point and
// measurement files): fields separated by spaces, tabs, commas (and semicolons where the
// caller allows them); blank lines and '#' comments skipped; every field must be a finite
// number, or CalibError names file:line and the field.
#include <cerrno>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

#include "calibration/lib/calib_error.hpp"

namespace arnav::calib {

struct NumericLineOptions {
  bool semicolons = false;         // ';' separates fields too (spreadsheet exports)
  bool header_line = false;        // a line starting with a letter before the first record is a header
};

// Calls row(values, line_no, at) for every data line; `at` is "source:line: " for messages.
template <typename Row>
void for_each_numeric_line(const std::string& text, const std::string& source, Row&& row,
                           NumericLineOptions options = {}) {
  std::istringstream in(text);
  std::string line;
  int line_no = 0;
  bool seen_record = false;
  while (std::getline(in, line)) {
    ++line_no;
    for (char& c : line) {
      if (c == ',' || c == '\t' || c == '\r' || (options.semicolons && c == ';')) c = ' ';
    }
    const auto first = line.find_first_not_of(' ');
    if (first == std::string::npos || line[first] == '#') continue;
    if (options.header_line && !seen_record && std::isalpha(static_cast<unsigned char>(line[first]))) continue;
    const std::string at = source + ":" + std::to_string(line_no) + ": ";
    std::vector<double> values;
    std::istringstream fields(line);
    std::string field;
    while (fields >> field) {
      char* end = nullptr;
      errno = 0;
      const double v = std::strtod(field.c_str(), &end);
      if (end == field.c_str() || *end != '\0' || errno == ERANGE || !std::isfinite(v)) {
        throw CalibError(at + "'" + field.substr(0, 40) + "' is not a finite number");
      }
      values.push_back(v);
    }
    seen_record = true;
    row(values, line_no, at);
  }
}

}  // namespace arnav::calib
