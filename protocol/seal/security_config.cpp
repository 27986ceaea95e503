#include "protocol/seal/security_config.hpp"

namespace arnav::seal {

namespace {
[[noreturn]] void fail(const YAML::Node& node, const std::string& source, const std::string& key, const std::string& what) {
  const int line = node.IsDefined() && node.Mark().line >= 0 ? node.Mark().line + 1 : 1;
  throw SecurityError(source + ":" + std::to_string(line) + ": key '" + key + "': " + what);
}
const char* kForm = "write 'security: {key_file: PATH}' (make the key with arnav-keygen PATH) or 'security: off' (bench and old logs only)";
}  // namespace

SecuritySettings parse_security(const YAML::Node& node, const std::string& source, const std::filesystem::path& base_dir) {
  SecuritySettings s;
  s.source = source;
  if (!node.IsDefined()) return s;
  s.line = node.Mark().line >= 0 ? node.Mark().line + 1 : 1;
  if (node.IsScalar()) {
    // YAML 1.1 reads a bare `off` as false; yaml-cpp keeps the text.
    if (node.Scalar() == "off" || node.Scalar() == "false") {
      s.mode = SecuritySettings::Mode::Off;
      return s;
    }
    fail(node, source, "security", "'" + node.Scalar() + "' is not a setting: " + kForm);
  }
  if (!node.IsMap()) fail(node, source, "security", std::string("expected a mapping: ") + kForm);
  for (const auto& kv : node) {
    const std::string k = kv.first.Scalar();
    if (k != "key_file" && k != "max_age_ms") fail(kv.first, source, "security." + k, "unknown key (known keys: key_file, max_age_ms)");
  }
  const YAML::Node file = node["key_file"];
  if (!file) fail(node, source, "security.key_file", std::string("missing: ") + kForm);
  if (!file.IsScalar() || file.Scalar().empty()) fail(file, source, "security.key_file", "expected a path to the key file");
  std::filesystem::path p(file.Scalar());
  s.key_file = (p.is_absolute() ? p : base_dir / p).lexically_normal().string();
  if (const YAML::Node age = node["max_age_ms"]) {
    double v = 0;
    try {
      v = age.as<double>();
    } catch (const YAML::Exception&) {
      fail(age, source, "security.max_age_ms", "expected a number of milliseconds, got '" + age.Scalar() + "'");
    }
    if (!(v >= 1.0 && v <= 600000.0)) fail(age, source, "security.max_age_ms", "must be between 1 and 600000");
    s.max_age_ms = static_cast<std::int64_t>(v);
  }
  s.mode = SecuritySettings::Mode::Sealed;
  return s;
}

std::string BusSecurity::describe() const {
  if (!key) return "security: OFF (messages neither authenticated nor encrypted: bench and old logs only)";
  return "security: sealed (XChaCha20-Poly1305, key id " + key->key_id_hex() + ", max age " + std::to_string(options.max_age_us / 1000) + " ms)";
}

BusSecurity resolve_security(const SecuritySettings& s) {
  BusSecurity b;
  switch (s.mode) {
    case SecuritySettings::Mode::Missing:
      throw SecurityError(s.source + ": key 'security': missing: the bus is sealed unless the configuration says otherwise; " + kForm);
    case SecuritySettings::Mode::Off: return b;
    case SecuritySettings::Mode::Sealed: break;
  }
  try {
    b.key = load_key(s.key_file);
  } catch (const KeyError& e) {
    throw SecurityError(s.source + ":" + std::to_string(s.line) + ": key 'security.key_file': " + e.what());
  }
  b.options.max_age_us = s.max_age_ms * 1000;
  return b;
}

BusSecurity security_from_cli(const std::string& key_file, const std::string& security, const std::string& program) {
  if (!key_file.empty() && !security.empty())
    throw SecurityError(program + ": give either --key FILE or --security off, not both");
  if (!security.empty()) {
    if (security != "off") throw SecurityError(program + ": --security takes only 'off' (to seal, give --key FILE)");
    return BusSecurity::off();
  }
  if (key_file.empty())
    throw SecurityError(program + ": the bus is sealed: give --key FILE (made by arnav-keygen), or --security off for a bench bus or an old log");
  BusSecurity b;
  try {
    b.key = load_key(key_file);
  } catch (const KeyError& e) {
    throw SecurityError(program + ": --key " + e.what());
  }
  return b;
}

}  // namespace arnav::seal
