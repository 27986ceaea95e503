#pragma once
// Line-aware reader for the text mesh formats (OBJ, OFF, TetGen, Gmsh, legacy VTK headers).
// Reads whitespace-separated tokens and remembers the line of the last token, so parse
// errors can name it. Also reads raw big-endian binary blocks (legacy VTK BINARY).
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace arnav::host {

class TextCursor {
 public:
  TextCursor(std::string_view text, std::string source) : text_(text), source_(std::move(source)) {}

  const std::string& source() const { return source_; }
  int line() const { return token_line_; }      // line of the last token read (1-based)
  std::size_t offset() const { return pos_; }
  bool at_end();                                // skips whitespace first

  // Next whitespace-separated token; throws naming the file and line at end of input.
  std::string_view token(const char* what);
  // Rest of the current line (without the newline), for comments and headers.
  std::string_view rest_of_line();
  // Skips blank lines and lines whose first non-blank character is `comment`.
  void skip_comment_lines(char comment);

  long long integer(const char* what);
  int index(const char* what);                  // an integer that fits an int
  double real(const char* what);                // rejects NaN and Inf

  // Binary block for legacy VTK BINARY: skips exactly one newline, then reads
  // big-endian values. Throws naming the byte offset if the data runs out.
  void skip_one_newline();
  float be_float(const char* what);
  double be_double(const char* what);
  std::int32_t be_int32(const char* what);

  [[noreturn]] void fail(const std::string& what, const std::string& fix) const;
  [[noreturn]] void fail_at_offset(const std::string& what, const std::string& fix) const;

 private:
  void skip_space();
  const unsigned char* need_bytes(std::size_t n, const char* what);

  std::string_view text_;
  std::string source_;
  std::size_t pos_ = 0;
  int line_ = 1;
  int token_line_ = 1;
};

}  // namespace arnav::host
