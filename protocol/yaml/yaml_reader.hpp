#pragma once
// Reading the appliance's YAML configuration (arnav-appliance's NDI keys, camera: and
// frames:) with one error style: "<file>:<line>: key '<key>': <what is wrong>", thrown as
// the caller's error type so each program maps it to its exit code. Unknown keys are
// errors: a typo must not fall back to a default.
#include <yaml-cpp/yaml.h>

#include <set>
#include <string>
#include <vector>

namespace arnav::yaml {

template <class Error>
class YamlReader {
 public:
  explicit YamlReader(std::string source) : source_(std::move(source)) {}

  // Parses text; the root must be a mapping.
  YAML::Node load_root(const std::string& text) const {
    YAML::Node root;
    try {
      root = YAML::Load(text);
    } catch (const YAML::ParserException& e) {
      throw Error(source_ + ":" + std::to_string(e.mark.line + 1) + ": YAML syntax error: " + e.msg);
    }
    if (!root.IsMap()) throw Error(source_ + ":1: the configuration must be a YAML mapping (key: value lines)");
    return root;
  }

  [[noreturn]] void fail(const YAML::Node& node, const std::string& key, const std::string& what) const {
    const int line = node.IsDefined() && node.Mark().line >= 0 ? node.Mark().line + 1 : 1;
    throw Error(source_ + ":" + std::to_string(line) + ": key '" + key + "': " + what);
  }

  // Rejects keys of `map` outside `known`; prefix names the section ("" at the top level).
  void only(const YAML::Node& map, const std::string& prefix, const std::set<std::string>& known) const {
    if (!map.IsMap()) fail(map, prefix, "expected a mapping (key: value lines)");
    for (const auto& kv : map) {
      const std::string key = kv.first.Scalar();
      if (!known.count(key)) {
        std::string list;
        for (const auto& k : known) list += (list.empty() ? "" : ", ") + k;
        fail(kv.first, prefix.empty() ? key : prefix + "." + key, "unknown key (known keys: " + list + ")");
      }
    }
  }

  template <typename T>
  T get(const YAML::Node& node, const std::string& key, const char* type_name) const {
    if (!node.IsScalar()) fail(node, key, std::string("expected ") + type_name);
    try {
      return node.as<T>();
    } catch (const YAML::Exception&) {
      fail(node, key, std::string("expected ") + type_name + ", got '" + node.Scalar() + "'");
    }
  }

  double number(const YAML::Node& map, const std::string& prefix, const char* key, double def, double lo, double hi) const {
    const YAML::Node n = map[key];
    if (!n) return def;
    const double v = get<double>(n, prefix + "." + key, "a number");
    if (!(v >= lo && v <= hi)) fail(n, prefix + "." + key, "must be between " + fmt(lo) + " and " + fmt(hi) + ", got " + n.Scalar());
    return v;
  }
  int integer(const YAML::Node& map, const std::string& prefix, const char* key, int def, int lo, int hi) const {
    const YAML::Node n = map[key];
    if (!n) return def;
    const int v = get<int>(n, prefix + "." + key, "an integer");
    if (v < lo || v > hi) fail(n, prefix + "." + key, "must be between " + std::to_string(lo) + " and " + std::to_string(hi) + ", got " + n.Scalar());
    return v;
  }
  bool boolean(const YAML::Node& map, const std::string& prefix, const char* key, bool def) const {
    const YAML::Node n = map[key];
    return n ? get<bool>(n, prefix + "." + key, "true or false") : def;
  }
  std::string text(const YAML::Node& map, const std::string& prefix, const char* key, const std::string& def) const {
    const YAML::Node n = map[key];
    return n ? get<std::string>(n, prefix + "." + key, "a string") : def;
  }
  std::vector<double> numbers(const YAML::Node& n, const std::string& key) const {
    if (!n.IsSequence()) fail(n, key, "expected a list of numbers");
    std::vector<double> out;
    for (std::size_t i = 0; i < n.size(); ++i) out.push_back(get<double>(n[i], key + "[" + std::to_string(i) + "]", "a number"));
    return out;
  }
  std::vector<std::string> strings(const YAML::Node& n, const std::string& key) const {
    if (!n.IsSequence()) fail(n, key, "expected a list of strings");
    std::vector<std::string> out;
    for (std::size_t i = 0; i < n.size(); ++i) out.push_back(get<std::string>(n[i], key + "[" + std::to_string(i) + "]", "a string"));
    return out;
  }

  static std::string fmt(double v) {
    std::string s = std::to_string(v);
    while (s.size() > 1 && s.back() == '0') s.pop_back();
    if (!s.empty() && s.back() == '.') s.pop_back();
    return s;
  }

 private:
  std::string source_;
};

}  // namespace arnav::yaml
