#include "host/register/basis_cache_file.hpp"

#include <nlohmann/json.hpp>

#include <bit>
#include <cmath>
#include <cstring>

#include "host/mesh/load_error.hpp"

namespace arnav::host {
namespace {

static_assert(std::endian::native == std::endian::little, "the basis cache file is little-endian");
constexpr char kMagic[8] = {'A', 'R', 'N', 'A', 'V', 'L', 'B', '1'};
constexpr std::uint64_t kMaxHeader = 1u << 20;  // 1 MiB of JSON is far more than any basis needs
constexpr std::uint64_t kMaxDofs = 300'000'000, kMaxModes = 100'000;

std::string hex64(std::uint64_t v) {
  static const char* d = "0123456789abcdef";
  std::string s(16, '0');
  for (int i = 15; i >= 0; --i, v >>= 4) s[static_cast<std::size_t>(i)] = d[v & 15];
  return s;
}

[[noreturn]] void bad(const std::string& name, const std::string& what) {
  throw LoadError(name + ": " + what + ". Fix: the load basis cache file is unusable; it is rebuilt (delete it, or the cache folder, if this repeats)");
}

// A whole number in [0, max] from the header. nlohmann converts a JSON float such as 3e76 to
// an integer type without a range check (undefined behaviour), so only integer JSON values
// are taken, and their range is checked here.
std::uint64_t whole_field(const nlohmann::json& h, const char* key, std::uint64_t max, const std::string& name) {
  const nlohmann::json& v = h.at(key);
  if (v.is_number_unsigned() && v.get<std::uint64_t>() <= max) return v.get<std::uint64_t>();
  if (v.is_number_integer() && v.get<std::int64_t>() >= 0 && static_cast<std::uint64_t>(v.get<std::int64_t>()) <= max)
    return static_cast<std::uint64_t>(v.get<std::int64_t>());
  bad(name, std::string("header field ") + key + " is " + v.dump() + ", not a whole number from 0 to " + std::to_string(max));
}

}  // namespace

std::uint64_t fnv1a64(std::string_view bytes, std::uint64_t h) {
  for (unsigned char c : bytes) {
    h ^= c;
    h *= 0x100000001b3ULL;
  }
  return h;
}

std::string serialize_load_basis(const LoadBasis& b, const std::string& key) {
  const std::uint64_t dofs = static_cast<std::uint64_t>(b.U.rows()), m = static_cast<std::uint64_t>(b.U.cols());
  std::string payload;
  payload.resize(8 * (dofs * m + m * m) + 4 * b.patch_of_vertex.size());
  char* p = payload.data();
  std::memcpy(p, b.U.data(), 8 * dofs * m);
  p += 8 * dofs * m;
  std::memcpy(p, b.G.data(), 8 * m * m);
  p += 8 * m * m;
  for (int v : b.patch_of_vertex) {
    const std::int32_t x = v;
    std::memcpy(p, &x, 4);
    p += 4;
  }
  nlohmann::json h = {{"format", "arnav load basis"},
                      {"version", kBasisCacheVersion},
                      {"key", key},
                      {"dofs", b.dofs},
                      {"modes", m},
                      {"patches", b.patches},
                      {"gravity", b.gravity},
                      {"support", b.support},
                      {"supported", b.supported},
                      {"stiffness_volume", b.stiffness_volume},
                      {"build_time_s", b.build_time_s},
                      {"mode_kind", b.mode_kind},
                      {"payload_bytes", payload.size()},
                      {"payload_checksum", hex64(fnv1a64(payload))}};
  const std::string header = h.dump(1) + "\n";
  std::string out(kMagic, 8);
  const std::uint64_t hl = header.size();
  out.append(reinterpret_cast<const char*>(&hl), 8);
  out += header;
  out += payload;
  return out;
}

LoadBasis parse_load_basis(std::string_view bytes, const std::string& expected_key, int expected_dofs, const std::string& name) {
  if (bytes.size() < 16 || std::memcmp(bytes.data(), kMagic, 8) != 0) bad(name, "not a load basis cache file (no ARNAVLB1 magic)");
  std::uint64_t hl = 0;
  std::memcpy(&hl, bytes.data() + 8, 8);
  if (hl > kMaxHeader || hl > bytes.size() - 16) bad(name, "header length " + std::to_string(hl) + " exceeds the file (" + std::to_string(bytes.size()) + " bytes): truncated");
  nlohmann::json h;
  try {
    h = nlohmann::json::parse(bytes.substr(16, hl));
  } catch (const nlohmann::json::exception& e) {
    bad(name, std::string("header is not valid JSON (") + e.what() + ")");
  }
  LoadBasis b;
  std::uint64_t dofs = 0, m = 0, payload_bytes = 0;
  std::string checksum, key;
  try {
    if (!h.is_object() || h.value("format", std::string()) != "arnav load basis") bad(name, "header format is not 'arnav load basis'");
    if (whole_field(h, "version", kMaxModes, name) != static_cast<std::uint64_t>(kBasisCacheVersion))
      bad(name, "format version " + h.at("version").dump() + ", this program reads " + std::to_string(kBasisCacheVersion) + " (stale)");
    key = h.at("key").get<std::string>();
    dofs = whole_field(h, "dofs", kMaxDofs, name);
    m = whole_field(h, "modes", kMaxModes, name);
    b.patches = static_cast<int>(whole_field(h, "patches", kMaxModes, name));
    b.gravity = static_cast<int>(whole_field(h, "gravity", kMaxModes, name));
    b.support = static_cast<int>(whole_field(h, "support", kMaxModes, name));
    b.supported = h.at("supported").get<bool>();
    b.stiffness_volume = h.at("stiffness_volume").get<double>();
    b.build_time_s = h.at("build_time_s").get<double>();
    b.mode_kind = h.at("mode_kind").get<std::vector<std::string>>();
    payload_bytes = whole_field(h, "payload_bytes", ~std::uint64_t{0}, name);
    checksum = h.at("payload_checksum").get<std::string>();
  } catch (const nlohmann::json::exception& e) {
    bad(name, std::string("header field missing or of the wrong type (") + e.what() + ")");
  }
  if (!expected_key.empty() && key != expected_key) bad(name, "key " + key + " is not the scene's " + expected_key + " (stale: built for other inputs)");
  if (dofs == 0 || dofs % 3 != 0 || dofs > kMaxDofs) bad(name, "dofs " + std::to_string(dofs) + " is not a positive multiple of 3");
  if (expected_dofs > 0 && dofs != static_cast<std::uint64_t>(expected_dofs))
    bad(name, "basis of " + std::to_string(dofs / 3) + " vertices, the scene has " + std::to_string(expected_dofs / 3) + " (stale)");
  if (m == 0 || m > kMaxModes) bad(name, "modes " + std::to_string(m) + " out of range");
  if (b.patches < 1 || b.gravity < 0 || b.support < 0 || b.patches > static_cast<int>(kMaxModes) || b.gravity > static_cast<int>(kMaxModes) ||
      b.support > static_cast<int>(kMaxModes) || static_cast<std::uint64_t>(3 * b.patches + b.gravity + b.support) != m)
    bad(name, "modes " + std::to_string(m) + " are not 3 x patches + gravity + support");
  if (b.mode_kind.size() != m) bad(name, std::to_string(b.mode_kind.size()) + " mode names for " + std::to_string(m) + " modes");
  if (!std::isfinite(b.stiffness_volume) || !(b.stiffness_volume > 0)) bad(name, "stiffness_volume is not a positive number");
  const std::uint64_t want = 8 * (dofs * m + m * m) + 4 * (dofs / 3);
  if (payload_bytes != want) bad(name, "payload_bytes " + std::to_string(payload_bytes) + " do not match the sizes (" + std::to_string(want) + ")");
  const std::uint64_t have = bytes.size() - 16 - hl;
  if (have != want) bad(name, "payload is " + std::to_string(have) + " bytes, the header says " + std::to_string(want) + (have < want ? " (truncated)" : ""));
  const std::string_view payload = bytes.substr(16 + hl);
  if (checksum != hex64(fnv1a64(payload))) bad(name, "payload checksum mismatch (corrupt)");
  b.dofs = static_cast<int>(dofs);
  b.U.resize(static_cast<Eigen::Index>(dofs), static_cast<Eigen::Index>(m));
  b.G.resize(static_cast<Eigen::Index>(m), static_cast<Eigen::Index>(m));
  const char* p = payload.data();
  std::memcpy(b.U.data(), p, 8 * dofs * m);
  p += 8 * dofs * m;
  std::memcpy(b.G.data(), p, 8 * m * m);
  p += 8 * m * m;
  b.patch_of_vertex.resize(dofs / 3);
  for (auto& v : b.patch_of_vertex) {
    std::int32_t x = 0;
    std::memcpy(&x, p, 4);
    p += 4;
    if (x < -1 || x >= b.patches) bad(name, "patch index " + std::to_string(x) + " out of range");
    v = x;
  }
  if (!b.U.allFinite() || !b.G.allFinite()) bad(name, "the basis holds NaN or Inf");
  return b;
}

}  // namespace arnav::host
