#include "appliance/synthetic_camera/phantom_recording.hpp"

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string_view>

namespace arnav::camera_sim {
namespace {

constexpr const char* kHeader = "# arnav phantom recording";
constexpr int kMaxVertices = 2000000, kMaxFaces = 4000000, kMaxFrames = 1000000, kMaxTools = 16, kMaxTargets = 64;

bool valid_name(std::string_view s) {
  if (s.empty() || s.size() > 64) return false;
  for (char c : s)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-')) return false;
  return true;
}

class Lines {
 public:
  Lines(const std::string& text, std::string source) : text_(text), source_(std::move(source)) {}

  [[noreturn]] void fail(const std::string& what) const {
    throw PhantomError(source_ + ":" + std::to_string(line_no_) + ": " + what);
  }
  // Next non-blank, non-comment line split into tokens; false at the end of the text.
  bool next(std::vector<std::string_view>& tokens) {
    while (pos_ < text_.size()) {
      const std::size_t end = text_.find('\n', pos_);
      const std::size_t stop = end == std::string::npos ? text_.size() : end;
      std::string_view line(text_.data() + pos_, stop - pos_);
      pos_ = stop + 1;
      ++line_no_;
      if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
      tokens.clear();
      std::size_t i = 0;
      while (i < line.size()) {
        while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
        std::size_t j = i;
        while (j < line.size() && line[j] != ' ' && line[j] != '\t') ++j;
        if (j > i) tokens.push_back(line.substr(i, j - i));
        i = j;
      }
      if (tokens.empty() || tokens[0].front() == '#') continue;
      return true;
    }
    ++line_no_;
    return false;
  }
  // Reads the next line, which must start with `key` and have `count` more tokens.
  void expect(std::vector<std::string_view>& tokens, std::string_view key, std::size_t count, const std::string& fix) {
    std::string k(key);
    if (!next(tokens)) fail(std::string("file ends where '").append(k).append("' was expected (truncated recording? ").append(fix).append(")"));
    if (tokens[0] != key) {
      std::string msg("expected '");
      msg.append(k).append("', found '").append(tokens[0].substr(0, 32)).append("' (").append(fix).append(")");
      fail(msg);
    }
    if (tokens.size() != count + 1) {
      std::string msg("'");
      msg.append(k).append("' takes ").append(std::to_string(count)).append(" value(s), found ").append(std::to_string(tokens.size() - 1));
      fail(msg);
    }
  }
  double number(std::string_view tok) const {
    const std::string s(tok.substr(0, 64));
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(s.c_str(), &end);
    if (tok.size() > 64 || end != s.c_str() + s.size() || s.empty() || errno == ERANGE || !std::isfinite(v))
      fail("'" + s + "' is not a finite number");
    return v;
  }
  long integer(std::string_view tok, long lo, long hi, const std::string& what) const {
    const std::string s(tok.substr(0, 32));
    char* end = nullptr;
    errno = 0;
    const long v = std::strtol(s.c_str(), &end, 10);
    if (tok.size() > 32 || s.empty() || end != s.c_str() + s.size() || errno == ERANGE)
      fail(what + ": '" + s + "' is not an integer");
    if (v < lo || v > hi) fail(what + " " + std::to_string(v) + " is outside [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
    return v;
  }
  int line_no() const { return line_no_; }

 private:
  const std::string& text_;
  std::string source_;
  std::size_t pos_ = 0;
  int line_no_ = 0;
};

void check_names(Lines& in, const std::vector<std::string_view>& tokens, std::vector<std::string>& names, const char* what) {
  for (std::size_t i = 2; i < tokens.size(); ++i) {
    if (!valid_name(tokens[i])) in.fail(std::string(what) + " name '" + std::string(tokens[i].substr(0, 64)) + "' must be 1-64 letters, digits, '_' or '-'");
    for (const auto& n : names)
      if (n == tokens[i]) in.fail(std::string(what) + " '" + n + "' is declared twice");
    names.emplace_back(tokens[i]);
  }
}

}  // namespace

int PhantomRecording::tool_index(const std::string& name) const {
  for (std::size_t i = 0; i < tool_names.size(); ++i)
    if (tool_names[i] == name) return static_cast<int>(i);
  return -1;
}

Eigen::Isometry3d PhantomRecording::tool_pose_at(double t_s, int index) const {
  if (frames.empty()) throw PhantomError("phantom recording: no frames");
  if (index < 0 || index >= static_cast<int>(tool_names.size())) throw PhantomError("phantom recording: no tool " + std::to_string(index));
  const auto i = static_cast<std::size_t>(index);
  if (!(t_s > frames.front().t_s)) return frames.front().X_ModelTool[i];
  if (t_s >= frames.back().t_s) return frames.back().X_ModelTool[i];
  std::size_t lo = 0, hi = frames.size() - 1;
  while (hi - lo > 1) {
    const std::size_t mid = (lo + hi) / 2;
    (frames[mid].t_s <= t_s ? lo : hi) = mid;
  }
  const Eigen::Isometry3d& a = frames[lo].X_ModelTool[i];
  const Eigen::Isometry3d& b = frames[hi].X_ModelTool[i];
  const double w = (t_s - frames[lo].t_s) / (frames[hi].t_s - frames[lo].t_s);
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = Eigen::Quaterniond(a.linear()).slerp(w, Eigen::Quaterniond(b.linear())).toRotationMatrix();
  X.translation() = (1 - w) * a.translation() + w * b.translation();
  return X;
}

PhantomFrame PhantomRecording::at(double t_s) const {
  if (frames.empty()) throw PhantomError("phantom recording: no frames");
  if (!(t_s > frames.front().t_s)) return frames.front();
  if (t_s >= frames.back().t_s) return frames.back();
  std::size_t lo = 0, hi = frames.size() - 1;
  while (hi - lo > 1) {
    const std::size_t mid = (lo + hi) / 2;
    (frames[mid].t_s <= t_s ? lo : hi) = mid;
  }
  const PhantomFrame& a = frames[lo];
  const PhantomFrame& b = frames[hi];
  const double w = (t_s - a.t_s) / (b.t_s - a.t_s);
  PhantomFrame f;
  f.t_s = t_s;
  for (std::size_t i = 0; i < a.X_ModelTool.size(); ++i) {
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.linear() = Eigen::Quaterniond(a.X_ModelTool[i].linear()).slerp(w, Eigen::Quaterniond(b.X_ModelTool[i].linear())).toRotationMatrix();
    X.translation() = (1 - w) * a.X_ModelTool[i].translation() + w * b.X_ModelTool[i].translation();
    f.X_ModelTool.push_back(X);
  }
  for (std::size_t i = 0; i < a.targets_Model_mm.size(); ++i)
    f.targets_Model_mm.push_back((1 - w) * a.targets_Model_mm[i] + w * b.targets_Model_mm[i]);
  f.vertices_Model_mm = (1 - w) * a.vertices_Model_mm + w * b.vertices_Model_mm;
  return f;
}

PhantomRecording parse_phantom_recording(const std::string& text, const std::string& source) {
  Lines in(text, source);
  PhantomRecording rec;
  std::vector<std::string_view> tok;
  {
    // The header is the first line, comment or not.
    const std::size_t end = text.find('\n');
    std::string_view first(text.data(), std::min<std::size_t>(end == std::string::npos ? text.size() : end, 200));
    if (!first.empty() && first.back() == '\r') first.remove_suffix(1);
    const std::string_view h = kHeader;
    if (first.size() <= h.size() || first.substr(0, h.size()) != h || first[h.size()] != ' ') {
      throw PhantomError(source + ":1: not a phantom recording (first line must be '" + std::string(h) + " 1'; write one with arnav-phantom-record)");
    }
    const std::string_view version = first.substr(h.size() + 1);
    if (version != "1") {
      throw PhantomError(source + ":1: phantom recording version '" + std::string(version.substr(0, 16)) +
                         "' is not supported (this build reads version 1; re-record with this build's arnav-phantom-record)");
    }
  }
  const std::string fix = "see appliance/synthetic_camera/phantom_recording.hpp for the layout";
  in.expect(tok, "frame", 1, fix);
  if (tok[1] != "Model") in.fail("frame must be 'Model' (the organ's model frame), found '" + std::string(tok[1].substr(0, 32)) + "'");
  if (!in.next(tok) || tok[0] != "tools" || tok.size() < 2) in.fail("expected 'tools N name...' (" + fix + ")");
  const long tools = in.integer(tok[1], 0, kMaxTools, "tool count");
  if (static_cast<long>(tok.size()) != tools + 2) in.fail("'tools " + std::to_string(tools) + "' needs " + std::to_string(tools) + " name(s)");
  check_names(in, tok, rec.tool_names, "tool");
  if (!in.next(tok) || tok[0] != "targets" || tok.size() < 2) in.fail("expected 'targets N name...' (" + fix + ")");
  const long targets = in.integer(tok[1], 1, kMaxTargets, "target count (the first is the tumour centroid)");
  if (static_cast<long>(tok.size()) != targets + 2) in.fail("'targets " + std::to_string(targets) + "' needs " + std::to_string(targets) + " name(s)");
  check_names(in, tok, rec.target_names, "target");
  in.expect(tok, "vertices", 1, fix);
  rec.vertex_count = static_cast<int>(in.integer(tok[1], 3, kMaxVertices, "vertex count"));
  // Each 'v' line takes at least 8 bytes: refuse counts the text cannot hold before allocating.
  if (static_cast<std::size_t>(rec.vertex_count) * 8 > text.size())
    in.fail("vertex count " + std::to_string(rec.vertex_count) + " cannot fit in a " + std::to_string(text.size()) +
            "-byte file (truncated recording?)");
  in.expect(tok, "faces", 1, fix);
  const long faces = in.integer(tok[1], 1, kMaxFaces, "face count");
  if (static_cast<std::size_t>(faces) * 8 > text.size())
    in.fail("face count " + std::to_string(faces) + " cannot fit in a " + std::to_string(text.size()) + "-byte file (truncated recording?)");
  for (long f = 0; f < faces; ++f) {
    in.expect(tok, "f", 3, "face " + std::to_string(f) + " of " + std::to_string(faces));
    Eigen::Vector3i v;
    for (int k = 0; k < 3; ++k) v[k] = static_cast<int>(in.integer(tok[1 + k], 0, rec.vertex_count - 1, "vertex index"));
    if (v[0] == v[1] || v[1] == v[2] || v[0] == v[2]) in.fail("face uses a vertex twice (degenerate triangle)");
    rec.faces.push_back(v);
  }
  in.expect(tok, "frames", 1, fix);
  const long frames = in.integer(tok[1], 1, kMaxFrames, "frame count");
  for (long k = 0; k < frames; ++k) {
    const std::string at = "frame " + std::to_string(k) + " of " + std::to_string(frames);
    PhantomFrame fr;
    in.expect(tok, "t", 1, at);
    fr.t_s = in.number(tok[1]);
    if (!rec.frames.empty() && !(fr.t_s > rec.frames.back().t_s)) in.fail("time " + std::string(tok[1]) + " s does not increase");
    for (const auto& name : rec.tool_names) {
      in.expect(tok, "tool", 8, at);
      if (tok[1] != name) in.fail("expected tool '" + name + "' (tools are listed in the declared order)");
      double v[7];
      for (int i = 0; i < 7; ++i) v[i] = in.number(tok[2 + i]);
      const Eigen::Quaterniond q(v[3], v[4], v[5], v[6]);
      if (std::abs(q.norm() - 1.0) > 1e-3) in.fail("tool quaternion is not unit (norm " + std::to_string(q.norm()) + ")");
      Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
      X.linear() = q.normalized().toRotationMatrix();
      X.translation() = Eigen::Vector3d(v[0], v[1], v[2]);
      fr.X_ModelTool.push_back(X);
    }
    for (const auto& name : rec.target_names) {
      in.expect(tok, "target", 4, at);
      if (tok[1] != name) in.fail("expected target '" + name + "' (targets are listed in the declared order)");
      fr.targets_Model_mm.emplace_back(in.number(tok[2]), in.number(tok[3]), in.number(tok[4]));
    }
    fr.vertices_Model_mm.resize(3, rec.vertex_count);
    for (int i = 0; i < rec.vertex_count; ++i) {
      in.expect(tok, "v", 3, at + ", vertex " + std::to_string(i) + " of " + std::to_string(rec.vertex_count));
      for (int c = 0; c < 3; ++c) fr.vertices_Model_mm(c, i) = in.number(tok[1 + c]);
    }
    rec.frames.push_back(std::move(fr));
  }
  if (in.next(tok)) in.fail("unexpected '" + std::string(tok[0].substr(0, 32)) + "' after the last frame (frame count too small?)");
  return rec;
}

PhantomRecording read_phantom_recording(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw PhantomError(path.string() + ": cannot read the phantom recording (make one with arnav-phantom-record, docs/hil.md)");
  std::ostringstream ss;
  ss << in.rdbuf();
  return parse_phantom_recording(ss.str(), path.string());
}

void write_phantom_recording(std::ostream& out, const PhantomRecording& rec) {
  if (rec.target_names.empty()) throw PhantomError("phantom recording: no target (the first is the tumour centroid)");
  for (const auto& f : rec.frames) {
    if (f.X_ModelTool.size() != rec.tool_names.size() || f.targets_Model_mm.size() != rec.target_names.size() ||
        f.vertices_Model_mm.cols() != rec.vertex_count)
      throw PhantomError("phantom recording: frame at " + std::to_string(f.t_s) + " s does not match the declared counts");
  }
  char buf[160];
  out << kHeader << " 1\nframe Model\ntools " << rec.tool_names.size();
  for (const auto& n : rec.tool_names) out << ' ' << n;
  out << "\ntargets " << rec.target_names.size();
  for (const auto& n : rec.target_names) out << ' ' << n;
  out << "\nvertices " << rec.vertex_count << "\nfaces " << rec.faces.size() << '\n';
  for (const auto& f : rec.faces) out << "f " << f[0] << ' ' << f[1] << ' ' << f[2] << '\n';
  out << "frames " << rec.frames.size() << '\n';
  for (const auto& f : rec.frames) {
    std::snprintf(buf, sizeof buf, "t %.6f\n", f.t_s);
    out << buf;
    for (std::size_t i = 0; i < rec.tool_names.size(); ++i) {
      const Eigen::Quaterniond q(f.X_ModelTool[i].linear());
      const Eigen::Vector3d p = f.X_ModelTool[i].translation();
      std::snprintf(buf, sizeof buf, "tool %s %.3f %.3f %.3f %.7f %.7f %.7f %.7f\n", rec.tool_names[i].c_str(), p.x(), p.y(), p.z(),
                    q.w(), q.x(), q.y(), q.z());
      out << buf;
    }
    for (std::size_t i = 0; i < rec.target_names.size(); ++i) {
      const Eigen::Vector3d& p = f.targets_Model_mm[i];
      std::snprintf(buf, sizeof buf, "target %s %.3f %.3f %.3f\n", rec.target_names[i].c_str(), p.x(), p.y(), p.z());
      out << buf;
    }
    for (int v = 0; v < rec.vertex_count; ++v) {
      std::snprintf(buf, sizeof buf, "v %.3f %.3f %.3f\n", f.vertices_Model_mm(0, v), f.vertices_Model_mm(1, v), f.vertices_Model_mm(2, v));
      out << buf;
    }
  }
}

void write_phantom_recording(const std::filesystem::path& path, const PhantomRecording& rec) {
  std::ofstream out(path, std::ios::binary);
  if (!out) throw PhantomError(path.string() + ": cannot create the phantom recording (check the folder exists and is writable)");
  write_phantom_recording(out, rec);
  out.flush();
  if (!out) throw PhantomError(path.string() + ": write failed (disk full?)");
}

}  // namespace arnav::camera_sim
