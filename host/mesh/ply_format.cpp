// Stanford PLY, ASCII, binary little- and big-endian: surfaces (parse_ply) and point clouds
// (parse_ply_points, used by host/register). Kept: vertex positions (x, y, z), vertex normals
// (nx, ny, nz) and the face vertex lists (vertex_indices or vertex_index); every other
// element and property (colours, texture coordinates, edges, materials) is read past by its
// declared type. Errors name the header line, the body line (ASCII) or
// the byte offset (binary).
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "host/mesh/load_error.hpp"
#include "host/mesh/mesh_formats.hpp"
#include "host/mesh/text_cursor.hpp"

namespace arnav::host {
namespace {

constexpr long long kMaxPlyCount = 1LL << 26;  // refuse absurd element counts before allocating
constexpr long long kMaxListLength = 1 << 16;   // refuse absurd polygon sizes

enum class PlyType { kInt8, kUInt8, kInt16, kUInt16, kInt32, kUInt32, kFloat32, kFloat64, kNone };

int type_size(PlyType t) {
  switch (t) {
    case PlyType::kInt8:
    case PlyType::kUInt8: return 1;
    case PlyType::kInt16:
    case PlyType::kUInt16: return 2;
    case PlyType::kInt32:
    case PlyType::kUInt32:
    case PlyType::kFloat32: return 4;
    case PlyType::kFloat64: return 8;
    case PlyType::kNone: return 0;
  }
  return 0;
}

PlyType parse_type(std::string_view s) {
  if (s == "char" || s == "int8") return PlyType::kInt8;
  if (s == "uchar" || s == "uint8") return PlyType::kUInt8;
  if (s == "short" || s == "int16") return PlyType::kInt16;
  if (s == "ushort" || s == "uint16") return PlyType::kUInt16;
  if (s == "int" || s == "int32") return PlyType::kInt32;
  if (s == "uint" || s == "uint32") return PlyType::kUInt32;
  if (s == "float" || s == "float32") return PlyType::kFloat32;
  if (s == "double" || s == "float64") return PlyType::kFloat64;
  return PlyType::kNone;
}

bool is_integer(PlyType t) { return t != PlyType::kFloat32 && t != PlyType::kFloat64; }

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::kNone;        // scalar type, or the item type of a list
  PlyType count_type = PlyType::kNone;  // kNone: a scalar property
  bool is_list() const { return count_type != PlyType::kNone; }
};

struct PlyElement {
  std::string name;
  long long count = 0;
  std::vector<PlyProperty> properties;
  int line = 0;  // header line that declared it
};

enum class PlyFormat { kAscii, kBinaryLittle, kBinaryBig };

// Reads values of the body, ASCII or binary, with the position for messages.
class PlyBody {
 public:
  PlyBody(std::string_view content, std::size_t start, int start_line, const std::string& source, PlyFormat format)
      : text_(content.substr(start), source), bytes_(content.substr(start)), source_(source), format_(format),
        start_offset_(start), start_line_(start_line) {}

  double value(PlyType t, const char* what) {
    if (format_ == PlyFormat::kAscii) {
      if (text_.at_end()) fail(std::string("unexpected end of file while reading ") + what, "the file is truncated or the header counts are wrong; re-export it");
      const std::string_view tok = text_.token(what);
      double v = 0.0;
      std::from_chars_result r{};
      if (is_integer(t)) {
        long long i = 0;
        r = std::from_chars(tok.data(), tok.data() + tok.size(), i);
        v = static_cast<double>(i);
      } else {
        r = std::from_chars(tok.data(), tok.data() + tok.size(), v);
      }
      if (r.ec != std::errc() || r.ptr != tok.data() + tok.size())
        fail(std::string("expected ") + (is_integer(t) ? "an integer" : "a number") + " for " + what + ", found '" +
                 std::string(tok.substr(0, 40)) + "'",
             "check the line for a missing or malformed value");
      return v;
    }
    const int n = type_size(t);
    if (pos_ + static_cast<std::size_t>(n) > bytes_.size())
      fail(std::string("the binary data ends while reading ") + what + " (" + std::to_string(bytes_.size() - pos_) +
               " bytes left)",
           "the file is truncated or the header counts are wrong; re-export it");
    unsigned char b[8];
    std::memcpy(b, bytes_.data() + pos_, n);
    pos_ += n;
    if (format_ == PlyFormat::kBinaryBig) std::reverse(b, b + n);  // to little-endian (x86)
    switch (t) {
      case PlyType::kInt8: return static_cast<std::int8_t>(b[0]);
      case PlyType::kUInt8: return b[0];
      case PlyType::kInt16: { std::int16_t v; std::memcpy(&v, b, 2); return v; }
      case PlyType::kUInt16: { std::uint16_t v; std::memcpy(&v, b, 2); return v; }
      case PlyType::kInt32: { std::int32_t v; std::memcpy(&v, b, 4); return v; }
      case PlyType::kUInt32: { std::uint32_t v; std::memcpy(&v, b, 4); return v; }
      case PlyType::kFloat32: { float v; std::memcpy(&v, b, 4); return static_cast<double>(v); }
      case PlyType::kFloat64: { double v; std::memcpy(&v, b, 8); return v; }
      case PlyType::kNone: break;
    }
    return 0.0;
  }

  // Skips `n` values of type t (binary: checks the bytes are there before moving on).
  void skip(PlyType t, long long n, const char* what) {
    if (format_ != PlyFormat::kAscii) {
      const unsigned long long bytes = static_cast<unsigned long long>(n) * static_cast<unsigned long long>(type_size(t));
      if (bytes > bytes_.size() - pos_)
        fail(std::string("the binary data ends while reading ") + what, "the file is truncated or the header counts are wrong; re-export it");
      pos_ += bytes;
      return;
    }
    for (long long k = 0; k < n; ++k) value(t, what);
  }

  // Line of the last value (ASCII) or 0 (binary).
  int line() const { return format_ == PlyFormat::kAscii ? start_line_ + text_.line() - 1 : 0; }

  [[noreturn]] void fail(const std::string& what, const std::string& fix) const {
    if (format_ == PlyFormat::kAscii) throw_load_error(source_, line(), what, fix);
    throw_load_error(source_, 0, what + " at byte offset " + std::to_string(start_offset_ + pos_), fix);
  }

  void finish() {
    if (format_ == PlyFormat::kAscii) {
      if (!text_.at_end()) fail("data after the last declared element", "fix the element counts in the header");
    } else if (pos_ != bytes_.size()) {
      fail(std::to_string(bytes_.size() - pos_) + " bytes after the last declared element",
           "fix the element counts in the header");
    }
  }

 private:
  TextCursor text_;
  std::string_view bytes_;
  const std::string& source_;
  PlyFormat format_;
  std::size_t pos_ = 0, start_offset_;
  int start_line_;
};

// The header: lines up to and including "end_header".
struct PlyHeader {
  PlyFormat format = PlyFormat::kAscii;
  std::vector<PlyElement> elements;
  std::size_t body_offset = 0;
  int body_line = 1;
};

PlyHeader parse_header(std::string_view content, const std::string& source) {
  PlyHeader h;
  std::size_t pos = 0;
  int line_no = 0;
  bool have_format = false;
  for (;;) {
    if (pos >= content.size())
      throw_load_error(source, line_no, "the header has no end_header line", "the file is truncated or not a PLY file");
    std::size_t end = content.find('\n', pos);
    if (end == std::string_view::npos) end = content.size();
    std::string_view line = content.substr(pos, end - pos);
    pos = std::min(end + 1, content.size());
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    std::vector<std::string_view> t;
    for (std::size_t i = 0; i < line.size();) {
      while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
      const std::size_t s = i;
      while (i < line.size() && line[i] != ' ' && line[i] != '\t') ++i;
      if (i > s) t.push_back(line.substr(s, i - s));
    }
    if (line_no == 1) {
      if (t.size() != 1 || t[0] != "ply") throw_load_error(source, 1, "not a PLY file (the first line must be 'ply')", "give a PLY surface");
      continue;
    }
    if (t.empty() || t[0] == "comment" || t[0] == "obj_info") continue;
    if (t[0] == "end_header") {
      h.body_offset = pos;
      h.body_line = line_no + 1;
      break;
    }
    if (t[0] == "format") {
      if (t.size() != 3) throw_load_error(source, line_no, "format line needs a format and a version", "e.g. 'format ascii 1.0'");
      if (t[1] == "ascii") h.format = PlyFormat::kAscii;
      else if (t[1] == "binary_little_endian") h.format = PlyFormat::kBinaryLittle;
      else if (t[1] == "binary_big_endian") h.format = PlyFormat::kBinaryBig;
      else throw_load_error(source, line_no, "unknown PLY format '" + std::string(t[1].substr(0, 40)) + "'",
                            "use ascii, binary_little_endian or binary_big_endian");
      if (t[2] != "1.0") throw_load_error(source, line_no, "unsupported PLY version '" + std::string(t[2].substr(0, 20)) + "'", "use version 1.0");
      have_format = true;
    } else if (t[0] == "element") {
      if (t.size() != 3) throw_load_error(source, line_no, "element line needs a name and a count", "e.g. 'element vertex 8'");
      long long n = -1;
      try {
        n = std::stoll(std::string(t[2].substr(0, 20)));
      } catch (const std::exception&) {
      }
      if (n < 0 || n > kMaxPlyCount || t[2].find_first_not_of("0123456789") != std::string_view::npos)
        throw_load_error(source, line_no, "bad element count '" + std::string(t[2].substr(0, 20)) + "'",
                         "the count must be a whole number up to " + std::to_string(kMaxPlyCount));
      h.elements.push_back(PlyElement{std::string(t[1].substr(0, 64)), n, {}, line_no});
    } else if (t[0] == "property") {
      if (h.elements.empty()) throw_load_error(source, line_no, "property before any element", "declare the element first");
      PlyProperty p;
      if (t.size() == 5 && t[1] == "list") {
        p.count_type = parse_type(t[2]);
        p.type = parse_type(t[3]);
        p.name = std::string(t[4].substr(0, 64));
        if (p.count_type == PlyType::kNone || !is_integer(p.count_type) || p.type == PlyType::kNone)
          throw_load_error(source, line_no, "bad list property types", "use e.g. 'property list uchar int vertex_indices'");
      } else if (t.size() == 3 && t[1] != "list") {
        p.type = parse_type(t[1]);
        p.name = std::string(t[2].substr(0, 64));
        if (p.type == PlyType::kNone)
          throw_load_error(source, line_no, "unknown property type '" + std::string(t[1].substr(0, 20)) + "'",
                           "use char, uchar, short, ushort, int, uint, float or double");
      } else {
        throw_load_error(source, line_no, "malformed property line", "use 'property TYPE NAME' or 'property list COUNT_TYPE TYPE NAME'");
      }
      h.elements.back().properties.push_back(std::move(p));
    } else {
      throw_load_error(source, line_no, "unknown header keyword '" + std::string(t[0].substr(0, 40)) + "'",
                       "the header may hold format, element, property, comment, obj_info and end_header");
    }
  }
  if (!have_format) throw_load_error(source, 2, "the header has no format line", "add e.g. 'format binary_little_endian 1.0'");
  return h;
}

}  // namespace

PlyPoints parse_ply_points(std::string_view content, const std::string& source, bool faces_required, ElementLines* face_lines) {
  const PlyHeader h = parse_header(content, source);
  const PlyElement* vertex = nullptr;
  const PlyElement* face = nullptr;
  for (const PlyElement& e : h.elements) {
    if (e.name == "vertex" && !vertex) vertex = &e;
    if (e.name == "face" && !face) face = &e;
  }
  if (!vertex) throw_load_error(source, 0, "the header declares no vertex element", "export the points or the surface with 'element vertex N'");
  if (faces_required && !face)
    throw_load_error(source, 0, "the header declares no vertex or no face element", "a surface needs both ('element vertex N', 'element face M')");
  // Scalar vertex properties kept: x y z (required) and nx ny nz (all three, or ignored).
  static const char* const kNames[6] = {"x", "y", "z", "nx", "ny", "nz"};
  int slot[6] = {-1, -1, -1, -1, -1, -1};
  for (int k = 0; k < static_cast<int>(vertex->properties.size()); ++k) {
    const PlyProperty& p = vertex->properties[k];
    for (int d = 0; d < 6; ++d)
      if (p.name == kNames[d] && !p.is_list()) slot[d] = k;
  }
  if (slot[0] < 0 || slot[1] < 0 || slot[2] < 0)
    throw_load_error(source, vertex->line, "the vertex element has no scalar x, y and z properties", "export the positions as x, y, z");
  const bool has_normals = slot[3] >= 0 && slot[4] >= 0 && slot[5] >= 0;
  int ids_property = -1;
  if (face) {
    for (int k = 0; k < static_cast<int>(face->properties.size()); ++k) {
      const PlyProperty& p = face->properties[k];
      if ((p.name == "vertex_indices" || p.name == "vertex_index") && p.is_list()) ids_property = k;
    }
    if (faces_required && (ids_property < 0 || !is_integer(face->properties[ids_property].type)))
      throw_load_error(source, face->line, "the face element has no integer list 'vertex_indices'",
                       "export faces as 'property list uchar int vertex_indices'");
    if (ids_property >= 0 && !is_integer(face->properties[ids_property].type)) ids_property = -1;
  }
  // Binary: a vertex row takes at least one byte per property, so the count cannot exceed
  // the bytes left (refuses a lying header before allocating).
  if (h.format != PlyFormat::kAscii && !vertex->properties.empty() &&
      static_cast<unsigned long long>(vertex->count) > (content.size() - h.body_offset) / vertex->properties.size())
    throw_load_error(source, 0,
                     "the header declares " + std::to_string(vertex->count) + " vertices, but only " +
                         std::to_string(content.size() - h.body_offset) + " bytes follow the header",
                     "the file is truncated, or the count in the header is wrong");

  PlyPoints out;
  out.mesh.positions_World_mm.resize(3, vertex->count);
  if (has_normals) out.normals.resize(3, vertex->count);
  PlyBody body(content, h.body_offset, h.body_line, source, h.format);
  for (const PlyElement& e : h.elements) {
    const bool is_vertex = &e == vertex, is_face = &e == face;
    for (long long i = 0; i < e.count; ++i) {
      for (int k = 0; k < static_cast<int>(e.properties.size()); ++k) {
        const PlyProperty& p = e.properties[k];
        if (!p.is_list()) {
          int d = -1;
          if (is_vertex)
            for (int s = 0; s < (has_normals ? 6 : 3); ++s)
              if (k == slot[s]) d = s;
          if (d < 0) {
            body.skip(p.type, 1, ("property " + p.name).c_str());
            continue;
          }
          const double v = body.value(p.type, d < 3 ? "a vertex coordinate" : "a vertex normal");
          if (!std::isfinite(v))
            body.fail("vertex " + std::to_string(i) + " has a non-finite " + kNames[d], "fix the values (NaN/Inf are not allowed; NaN often marks missing depth)");
          if (d < 3) out.mesh.positions_World_mm(d, i) = v;
          else out.normals(d - 3, i) = v;
          if (d == 0) out.vertex_lines.push_back(body.line());
          continue;
        }
        const double n_value = body.value(p.count_type, ("the length of list " + p.name).c_str());
        const int line = body.line();
        if (n_value < 0 || n_value > kMaxListLength)
          body.fail("list " + p.name + " of " + e.name + " " + std::to_string(i) + " has length " + std::to_string(static_cast<long long>(n_value)),
                    "lengths must be 0.." + std::to_string(kMaxListLength));
        const long long n = static_cast<long long>(n_value);
        if (!(is_face && k == ids_property)) {
          body.skip(p.type, n, ("list " + p.name).c_str());
          continue;
        }
        if (n < 3) body.fail("face " + std::to_string(i) + " has " + std::to_string(n) + " vertices", "faces need 3 or more");
        std::vector<int> ids(static_cast<std::size_t>(n));
        for (int& id : ids) {
          const double v = body.value(p.type, "a face vertex index");
          if (v < 0 || v >= static_cast<double>(vertex->count))
            body.fail("face " + std::to_string(i) + " refers to vertex " + std::to_string(static_cast<long long>(v)) + " of " +
                          std::to_string(vertex->count),
                      "vertex indices are 0-based and below the vertex count");
          id = static_cast<int>(v);
        }
        for (std::size_t a = 1; a + 1 < ids.size(); ++a) {
          out.mesh.tris.push_back({ids[0], ids[a], ids[a + 1]});
          if (face_lines) face_lines->push_back(line);
        }
      }
    }
  }
  body.finish();
  return out;
}

TriMesh parse_ply(std::string_view content, const std::string& source, ElementLines* lines) {
  return parse_ply_points(content, source, true, lines).mesh;
}

}  // namespace arnav::host
