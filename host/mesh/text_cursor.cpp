#include "host/mesh/text_cursor.hpp"

#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>

#include "host/mesh/load_error.hpp"

namespace arnav::host {
namespace {
bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v'; }
}  // namespace

void TextCursor::skip_space() {
  while (pos_ < text_.size() && is_space(text_[pos_])) {
    if (text_[pos_] == '\n') ++line_;
    ++pos_;
  }
}

bool TextCursor::at_end() {
  skip_space();
  return pos_ >= text_.size();
}

std::string_view TextCursor::token(const char* what) {
  skip_space();
  if (pos_ >= text_.size()) {
    token_line_ = line_;
    fail(std::string("unexpected end of file while reading ") + what, "the file is truncated; re-export it");
  }
  const std::size_t start = pos_;
  while (pos_ < text_.size() && !is_space(text_[pos_])) ++pos_;
  token_line_ = line_;
  return text_.substr(start, pos_ - start);
}

std::string_view TextCursor::rest_of_line() {
  while (pos_ < text_.size() && (text_[pos_] == ' ' || text_[pos_] == '\t')) ++pos_;
  const std::size_t start = pos_;
  while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
  token_line_ = line_;
  std::string_view out = text_.substr(start, pos_ - start);
  if (!out.empty() && out.back() == '\r') out.remove_suffix(1);
  return out;
}

void TextCursor::skip_comment_lines(char comment) {
  for (;;) {
    skip_space();
    if (pos_ < text_.size() && text_[pos_] == comment) {
      while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
    } else {
      return;
    }
  }
}

long long TextCursor::integer(const char* what) {
  const std::string_view t = token(what);
  long long value = 0;
  const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), value);
  if (ec != std::errc() || end != t.data() + t.size()) {
    fail(std::string("expected an integer for ") + what + ", found '" + std::string(t.substr(0, 40)) + "'",
         "check the line for a missing or extra value");
  }
  return value;
}

int TextCursor::index(const char* what) {
  const long long v = integer(what);
  if (v < std::numeric_limits<int>::min() || v > std::numeric_limits<int>::max()) {
    fail(std::string(what) + " " + std::to_string(v) + " is out of range", "use indices below 2^31");
  }
  return static_cast<int>(v);
}

double TextCursor::real(const char* what) {
  const std::string_view t = token(what);
  double value = 0;
  const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), value);
  if (ec != std::errc() || end != t.data() + t.size()) {
    fail(std::string("expected a number for ") + what + ", found '" + std::string(t.substr(0, 40)) + "'",
         "check the line for a missing or malformed value");
  }
  if (!std::isfinite(value)) {
    fail(std::string(what) + " is not finite (" + std::string(t) + ")", "replace NaN/Inf coordinates with real values");
  }
  return value;
}

void TextCursor::skip_one_newline() {
  while (pos_ < text_.size() && (text_[pos_] == ' ' || text_[pos_] == '\t' || text_[pos_] == '\r')) ++pos_;
  if (pos_ < text_.size() && text_[pos_] == '\n') {
    ++pos_;
    ++line_;
  }
}

const unsigned char* TextCursor::need_bytes(std::size_t n, const char* what) {
  if (text_.size() - pos_ < n) {
    fail_at_offset(std::string("binary data ends while reading ") + what,
                   "the file is truncated or its header counts are too large; re-export it");
  }
  const auto* p = reinterpret_cast<const unsigned char*>(text_.data() + pos_);
  for (std::size_t i = 0; i < n; ++i)
    if (p[i] == '\n') ++line_;  // keep line numbers meaningful for text that follows
  pos_ += n;
  return p;
}

float TextCursor::be_float(const char* what) {
  const unsigned char* p = need_bytes(4, what);
  const std::uint32_t bits = (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) | p[3];
  float f;
  std::memcpy(&f, &bits, 4);
  return f;
}

double TextCursor::be_double(const char* what) {
  const unsigned char* p = need_bytes(8, what);
  std::uint64_t bits = 0;
  for (int i = 0; i < 8; ++i) bits = (bits << 8) | p[i];
  double d;
  std::memcpy(&d, &bits, 8);
  return d;
}

std::int32_t TextCursor::be_int32(const char* what) {
  const unsigned char* p = need_bytes(4, what);
  const std::uint32_t bits = (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) | p[3];
  std::int32_t v;
  std::memcpy(&v, &bits, 4);
  return v;
}

void TextCursor::fail(const std::string& what, const std::string& fix) const {
  throw_load_error(source_, token_line_, what, fix);
}

void TextCursor::fail_at_offset(const std::string& what, const std::string& fix) const {
  throw_load_error(source_, 0, "byte offset " + std::to_string(pos_) + ": " + what,
                   fix);
}

}  // namespace arnav::host
