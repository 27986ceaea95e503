#include "appliance/ndi/transcript.hpp"

#include <algorithm>
#include <charconv>
#include <cstdlib>
#include <cmath>
#include <fstream>
#include <istream>
#include <ostream>

#include "appliance/ndi/hex.hpp"

namespace arnav::ndi {
namespace {

[[noreturn]] void fail(std::string_view source, int line, const std::string& what) {
  throw TranscriptError(std::string(source) + ":" + std::to_string(line) + ": " + what);
}

std::optional<std::int64_t> parse_int(std::string_view s) {
  std::int64_t v = 0;
  if (s.empty()) return std::nullopt;
  auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || ptr != s.data() + s.size()) return std::nullopt;
  return v;
}

}  // namespace

std::string_view to_string(TranscriptRecord::Kind kind) {
  switch (kind) {
    case TranscriptRecord::Kind::Command: return "cmd";
    case TranscriptRecord::Kind::Reply: return "reply";
    case TranscriptRecord::Kind::Baud: return "baud";
    case TranscriptRecord::Kind::Break: return "break";
    case TranscriptRecord::Kind::Note: return "note";
  }
  return "?";
}

std::string escape_bytes(std::string_view bytes) {
  static constexpr char kDigits[] = "0123456789ABCDEF";
  std::string out;
  out.reserve(bytes.size() + 8);
  for (std::size_t i = 0; i < bytes.size(); ++i) {
    const auto b = static_cast<unsigned char>(bytes[i]);
    if (b == '\\') out += "\\\\";
    else if (b == '\r') out += "\\r";
    else if (b == '\n') out += "\\n";
    else if (b == '\t') out += "\\t";
    else if (b >= 0x20 && b < 0x7F && !(b == ' ' && i + 1 == bytes.size())) out += static_cast<char>(b);
    else {
      out += "\\x";
      out += kDigits[b >> 4];
      out += kDigits[b & 0xF];
    }
  }
  return out;
}

std::optional<std::string> unescape_bytes(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (c != '\\') {
      out += c;
      continue;
    }
    if (++i >= text.size()) return std::nullopt;
    switch (text[i]) {
      case '\\': out += '\\'; break;
      case 'r': out += '\r'; break;
      case 'n': out += '\n'; break;
      case 't': out += '\t'; break;
      case 'x': {
        if (i + 2 >= text.size()) return std::nullopt;
        auto v = parse_hex<std::uint8_t>(text.substr(i + 1, 2));
        if (!v) return std::nullopt;
        out += static_cast<char>(*v);
        i += 2;
        break;
      }
      default: return std::nullopt;
    }
  }
  return out;
}

std::vector<TranscriptRecord> read_transcript(std::istream& in, std::string_view source) {
  std::vector<TranscriptRecord> records;
  std::string line;
  int line_no = 0;
  bool header_seen = false;
  std::int64_t last_t = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (!header_seen) {
      std::string_view l(line);
      if (!l.empty() && l.back() == '\r') l.remove_suffix(1);
      if (l != kTranscriptHeader)
        fail(source, line_no, "not an arnav-ndi transcript: the first line must be '" + std::string(kTranscriptHeader) + "'");
      header_seen = true;
      continue;
    }
    if (line.empty() || line[0] == '#') continue;
    std::string_view l(line);
    const std::size_t sp1 = l.find(' ');
    if (sp1 == std::string_view::npos) fail(source, line_no, "expected '<t_us> <kind> ...'");
    auto t = parse_int(l.substr(0, sp1));
    if (!t || *t < 0) fail(source, line_no, "time '" + std::string(l.substr(0, sp1)) + "' is not a non-negative integer (microseconds)");
    if (*t < last_t) fail(source, line_no, "time goes backwards (" + std::to_string(*t) + " after " + std::to_string(last_t) + ")");
    last_t = *t;
    std::string_view rest = l.substr(sp1 + 1);
    const std::size_t sp2 = rest.find(' ');
    std::string_view kind = rest.substr(0, sp2);
    std::string_view payload = sp2 == std::string_view::npos ? std::string_view{} : rest.substr(sp2 + 1);
    TranscriptRecord r;
    r.t_us = *t;
    r.line = line_no;
    if (kind == "cmd" || kind == "reply" || kind == "note") {
      r.kind = kind == "cmd" ? TranscriptRecord::Kind::Command
               : kind == "reply" ? TranscriptRecord::Kind::Reply : TranscriptRecord::Kind::Note;
      auto bytes = unescape_bytes(payload);
      if (!bytes) fail(source, line_no, "malformed escape in '" + std::string(payload) + "' (use \\\\ \\r \\n \\t \\xHH)");
      if (bytes->empty() && r.kind != TranscriptRecord::Kind::Note) fail(source, line_no, "empty " + std::string(kind) + " record");
      r.bytes = std::move(*bytes);
    } else if (kind == "baud" || kind == "break") {
      r.kind = kind == "baud" ? TranscriptRecord::Kind::Baud : TranscriptRecord::Kind::Break;
      auto v = parse_int(payload);
      if (!v || *v < 0 || (r.kind == TranscriptRecord::Kind::Baud && *v == 0))
        fail(source, line_no, std::string(kind) + " needs a positive integer, got '" + std::string(payload) + "'");
      r.value = *v;
    } else {
      fail(source, line_no, "unknown record kind '" + std::string(kind) + "' (cmd, reply, baud, break, note)");
    }
    records.push_back(std::move(r));
  }
  if (!header_seen) fail(source, 1, "empty file: not an arnav-ndi transcript");
  return records;
}

std::vector<TranscriptRecord> read_transcript_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw TranscriptError(path.string() + ": cannot open transcript");
  return read_transcript(in, path.string());
}

std::string format_record(const TranscriptRecord& r) {
  std::string out = std::to_string(r.t_us) + " " + std::string(to_string(r.kind)) + " ";
  switch (r.kind) {
    case TranscriptRecord::Kind::Baud:
    case TranscriptRecord::Kind::Break: out += std::to_string(r.value); break;
    default: out += escape_bytes(r.bytes); break;
  }
  return out;
}

void write_transcript(std::ostream& out, const std::vector<TranscriptRecord>& records) {
  out << kTranscriptHeader << '\n';
  for (const auto& r : records) out << format_record(r) << '\n';
}

std::vector<TranscriptRecord> import_igstk_log(std::istream& in, std::string_view source) {
  std::vector<TranscriptRecord> records;
  std::string line;
  int line_no = 0;
  std::optional<double> t0;
  while (std::getline(in, line)) {
    ++line_no;
    std::string_view l(line);
    bool is_cmd = false;
    std::size_t tag = l.find(". command[");
    if (tag != std::string_view::npos) {
      is_cmd = true;
      tag += 10;
    } else if ((tag = l.find(". receive[")) != std::string_view::npos) {
      tag += 10;
    } else {
      continue;  // comments, debug lines
    }
    const std::size_t close = l.find("] ", tag);
    if (close == std::string_view::npos) fail(source, line_no, "missing ']' after the byte count");
    auto len = parse_int(l.substr(tag, close - tag));
    if (!len) fail(source, line_no, "byte count is not an integer");
    // IGSTK writes \xNN and \\ like the transcript format does.
    auto bytes = unescape_bytes(l.substr(close + 2));
    if (!bytes) fail(source, line_no, "malformed escape");
    if (static_cast<std::int64_t>(bytes->size()) != *len)
      fail(source, line_no, "byte count " + std::to_string(*len) + " but " + std::to_string(bytes->size()) + " bytes logged");
    double t = 0.0;
    {
      const std::string stamp(l.substr(0, l.find(' ')));
      char* end = nullptr;
      t = std::strtod(stamp.c_str(), &end);
      if (end == stamp.c_str()) fail(source, line_no, "line does not start with a time stamp");
    }
    if (!t0) t0 = t;
    TranscriptRecord r;
    r.kind = is_cmd ? TranscriptRecord::Kind::Command : TranscriptRecord::Kind::Reply;
    r.t_us = std::max<std::int64_t>(records.empty() ? 0 : records.back().t_us, std::llround((t - *t0) * 1e6));
    r.bytes = std::move(*bytes);
    r.line = line_no;
    records.push_back(std::move(r));
  }
  return records;
}

}  // namespace arnav::ndi
