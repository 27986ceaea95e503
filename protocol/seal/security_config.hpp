#pragma once
// The `security:` key every program on the bus reads from its configuration
// (docs/protocol.md, "Sealed bus"):
//   security: {key_file: bus.key}          # sealed (path relative to the config file)
//   security: {key_file: bus.key, max_age_ms: 2000}
//   security: off                          # bench and old logs only: announced everywhere
// A configuration without the key does not start: there is no silent default.
#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>

#include "protocol/seal/channel_guard.hpp"
#include "protocol/seal/key.hpp"

namespace arnav::seal {

class SecurityError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct SecuritySettings {
  enum class Mode { Missing, Off, Sealed };
  Mode mode = Mode::Missing;
  std::string key_file;  // resolved against the configuration's folder
  std::int64_t max_age_ms = 2000;
  std::string source;  // the configuration file
  int line = 1;
};

// Reads node (the value of `security:`, undefined when the key is absent). Throws
// SecurityError "<source>:<line>: key 'security...': <what>" for a bad value.
SecuritySettings parse_security(const YAML::Node& node, const std::string& source, const std::filesystem::path& base_dir);

// What a bus instance runs with: a key (sealed) or none (security: off).
struct BusSecurity {
  std::shared_ptr<const SessionKey> key;
  OpenerOptions options;
  bool sealed() const { return key != nullptr; }
  // One line for start-up and status lines: "security: sealed (XChaCha20-Poly1305, key id
  // 0a1b2c3d)" or "security: OFF (...)".
  std::string describe() const;
  static BusSecurity off() { return {}; }
};

// Loads the key the settings name. Throws SecurityError (naming the file and the fix) when
// the configuration says nothing about security or the key file is unusable.
BusSecurity resolve_security(const SecuritySettings& settings);

// For programs configured on the command line (--key FILE or --security off).
BusSecurity security_from_cli(const std::string& key_file, const std::string& security, const std::string& program);

}  // namespace arnav::seal
