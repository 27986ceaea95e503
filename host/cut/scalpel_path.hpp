#pragma once
// A recorded or planned scalpel path for arnav-sim --scalpel: CSV with header
//   t_s,tip_x,tip_y,tip_z,heel_x,heel_y,heel_z[,cutting]
// (World frame, mm, s; cutting 0/1, default 1), times strictly increasing. The blade at a
// time is the linear interpolation of the two samples around it (the first/last sample
// before/after the path; cutting takes the earlier sample's flag).
#include <string>
#include <vector>

#include "host/cut/blade.hpp"

namespace arnav::host::cut {

struct ScalpelSample {
  double t_s = 0.0;
  BladeSegment blade;
  bool cutting = true;
};

struct ScalpelPath {
  std::vector<ScalpelSample> samples;  // at least one, times increasing
  // Blade and cutting flag at time t_s.
  ScalpelSample at(double t_s) const;
};

// Parses the CSV text; throws LoadError "<source>:<line>: ... Fix: ...".
ScalpelPath parse_scalpel_csv(const std::string& text, const std::string& source);
// Reads and parses a file; throws LoadError naming the file when it cannot be read.
ScalpelPath load_scalpel_csv(const std::string& path);

}  // namespace arnav::host::cut
