#pragma once
// Opening step shared by ARNav's own YAML file formats (board layouts, transform files):
// parse, require a map, require the supported format version. Errors name the file.
#include <string>

#include <yaml-cpp/yaml.h>

namespace arnav::calib {

// Returns the root map; throws CalibError naming `source` (and the line for syntax
// errors) when the text is not YAML, not a map, or `version_key` is not 1.
YAML::Node load_versioned_yaml(const std::string& yaml_text, const std::string& source, const std::string& what,
                               const std::string& version_key);

}  // namespace arnav::calib
