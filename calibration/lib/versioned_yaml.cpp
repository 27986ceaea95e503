#include "calibration/lib/versioned_yaml.hpp"

#include "calibration/lib/calib_error.hpp"

namespace arnav::calib {

YAML::Node load_versioned_yaml(const std::string& yaml_text, const std::string& source, const std::string& what,
                               const std::string& version_key) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::Exception& e) {
    throw CalibError(source + ":" + std::to_string(e.mark.line + 1) + ": not valid YAML (" + e.msg + ")");
  }
  if (!root.IsMap()) throw CalibError(source + ": expected a YAML map (" + what + ")");
  const YAML::Node v = root[version_key];
  int version = 0;
  try {
    if (!v) throw CalibError(source + ": missing key '" + version_key + "'");
    version = v.as<int>();
  } catch (const YAML::Exception&) {
    throw CalibError(source + ":" + std::to_string(v.Mark().line + 1) + ": key '" + version_key +
                     "' has the wrong type");
  }
  if (version != 1) {
    throw CalibError(source + ": " + version_key + " " + std::to_string(version) +
                     " is not supported (this build reads version 1)");
  }
  return root;
}

}  // namespace arnav::calib
