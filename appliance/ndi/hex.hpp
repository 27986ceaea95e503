#pragma once
// Fixed-width hexadecimal and signed-decimal field readers for ASCII replies.
// Strict: every character must be a digit of the field (no spaces, no prefixes).
#include <cstdint>
#include <optional>
#include <string_view>

namespace arnav::ndi {

inline int hex_digit(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return -1;
}

template <typename T>
std::optional<T> parse_hex(std::string_view s) {
  if (s.empty() || s.size() > 2 * sizeof(T)) return std::nullopt;
  std::uint64_t v = 0;
  for (char c : s) {
    int d = hex_digit(c);
    if (d < 0) return std::nullopt;
    v = (v << 4) | static_cast<unsigned>(d);
  }
  return static_cast<T>(v);
}

// "+01234" style: a sign then decimal digits; returns the integer value.
inline std::optional<long> parse_signed_decimal(std::string_view s) {
  if (s.size() < 2 || (s[0] != '+' && s[0] != '-')) return std::nullopt;
  long v = 0;
  for (char c : s.substr(1)) {
    if (c < '0' || c > '9') return std::nullopt;
    v = v * 10 + (c - '0');
  }
  return s[0] == '-' ? -v : v;
}

}  // namespace arnav::ndi
