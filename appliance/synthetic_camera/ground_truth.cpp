#include "appliance/synthetic_camera/ground_truth.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <sstream>

namespace arnav::camera_sim {
namespace {

constexpr const char* kHeader = "# arnav camera ground truth 1";
constexpr const char* kColumns = "sequence,time_s,board,x_mm,y_mm,z_mm,qw,qx,qy,qz,tags_visible,frame_file";
constexpr const char* kHeader2 = "# arnav camera ground truth 2";
constexpr const char* kColumns2 = "sequence,time_s,board,x_mm,y_mm,z_mm,qw,qx,qy,qz,tags_visible,frame_file,u_px,v_px";

double to_double(const std::string& s, const std::string& where, const char* column) {
  double v = 0.0;
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || ptr != s.data() + s.size() || !std::isfinite(v)) {
    throw GroundTruthError(where + ": column " + column + ": '" + s + "' is not a finite number");
  }
  return v;
}

std::int64_t to_int(const std::string& s, const std::string& where, const char* column) {
  std::int64_t v = 0;
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || ptr != s.data() + s.size()) {
    throw GroundTruthError(where + ": column " + column + ": '" + s + "' is not an integer");
  }
  return v;
}

}  // namespace

GroundTruthWriter::GroundTruthWriter(const std::filesystem::path& path, int version) : path_(path), out_(path), version_(version) {
  if (version != 1 && version != 2) throw GroundTruthError(path.string() + ": ground-truth version must be 1 or 2");
  if (!out_) throw GroundTruthError(path.string() + ": cannot create the ground-truth file (folder missing or read-only?)");
  out_ << (version == 2 ? kHeader2 : kHeader) << "\n" << (version == 2 ? kColumns2 : kColumns) << "\n";
  out_.flush();
}

void GroundTruthWriter::write(const GroundTruthRow& row) {
  const Eigen::Quaterniond q(row.X_CamBoard.linear());
  const Eigen::Quaterniond qp = q.w() < 0 ? Eigen::Quaterniond(-q.coeffs()) : q;
  const Eigen::Vector3d p = row.X_CamBoard.translation();
  char buf[512];
  std::snprintf(buf, sizeof buf, "%lld,%.6f,%s,%.6f,%.6f,%.6f,%.9f,%.9f,%.9f,%.9f,%d,%s",
                static_cast<long long>(row.sequence), row.time_s, row.board.c_str(), p.x(), p.y(), p.z(), qp.w(), qp.x(),
                qp.y(), qp.z(), row.tags_visible, row.frame_file.c_str());
  out_ << buf;
  if (version_ == 2) {
    if (row.has_px) {
      std::snprintf(buf, sizeof buf, ",%.4f,%.4f", row.u_px, row.v_px);
      out_ << buf;
    } else {
      out_ << ",,";
    }
  } else if (row.has_px || row.is_target()) {
    throw GroundTruthError(path_.string() + ": target rows need a version 2 ground-truth file");
  }
  out_ << '\n';
  out_.flush();
  if (!out_) throw GroundTruthError(path_.string() + ": write failed (disk full?)");
}

std::vector<GroundTruthRow> parse_ground_truth(const std::string& text, const std::string& source) {
  std::vector<GroundTruthRow> rows;
  std::istringstream in(text);
  std::string line;
  int line_no = 0;
  int version = 1;
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const std::string where = source + ":" + std::to_string(line_no);
    if (line_no == 1) {
      if (line == kHeader2) version = 2;
      else if (line != kHeader) throw GroundTruthError(where + ": expected '" + std::string(kHeader) + "' or '" + kHeader2 + "'");
      continue;
    }
    if (line_no == 2) {
      const char* cols = version == 2 ? kColumns2 : kColumns;
      if (line != cols) throw GroundTruthError(where + ": expected the column line '" + std::string(cols) + "'");
      continue;
    }
    if (line.empty()) continue;
    std::vector<std::string> f;
    std::string cell;
    std::istringstream cells(line);
    while (std::getline(cells, cell, ',')) f.push_back(cell);
    if (!line.empty() && line.back() == ',') f.emplace_back();
    const std::size_t columns = version == 2 ? 14 : 12;
    if (f.size() != columns) {
      throw GroundTruthError(where + ": " + std::to_string(f.size()) + " columns, expected " + std::to_string(columns));
    }
    GroundTruthRow r;
    r.sequence = to_int(f[0], where, "sequence");
    r.time_s = to_double(f[1], where, "time_s");
    r.board = f[2];
    if (r.board.empty()) throw GroundTruthError(where + ": column board is empty");
    const Eigen::Vector3d p(to_double(f[3], where, "x_mm"), to_double(f[4], where, "y_mm"), to_double(f[5], where, "z_mm"));
    Eigen::Quaterniond q(to_double(f[6], where, "qw"), to_double(f[7], where, "qx"), to_double(f[8], where, "qy"),
                         to_double(f[9], where, "qz"));
    if (std::abs(q.norm() - 1.0) > 1e-6) {
      throw GroundTruthError(where + ": quaternion norm " + std::to_string(q.norm()) + " is not 1");
    }
    r.X_CamBoard.linear() = q.normalized().toRotationMatrix();
    r.X_CamBoard.translation() = p;
    const std::int64_t tags = to_int(f[10], where, "tags_visible");
    if (tags < 0 || tags > 100000) throw GroundTruthError(where + ": tags_visible " + f[10] + " out of range");
    r.tags_visible = static_cast<int>(tags);
    r.frame_file = f[11];
    if (version == 2) {
      if (f[12].empty() != f[13].empty()) throw GroundTruthError(where + ": u_px and v_px must both be given or both be empty");
      if (!f[12].empty()) {
        r.has_px = true;
        r.u_px = to_double(f[12], where, "u_px");
        r.v_px = to_double(f[13], where, "v_px");
      }
      if (r.is_target() && !r.has_px) throw GroundTruthError(where + ": target row without u_px,v_px");
    } else if (r.is_target()) {
      throw GroundTruthError(where + ": target rows need the version 2 header '" + std::string(kHeader2) + "'");
    }
    rows.push_back(r);
  }
  if (line_no < 2) throw GroundTruthError(source + ":" + std::to_string(line_no + 1) + ": header or column line missing");
  return rows;
}

std::vector<GroundTruthRow> read_ground_truth(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw GroundTruthError(path.string() + ": cannot open the ground-truth file");
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_ground_truth(ss.str(), path.string());
}

}  // namespace arnav::camera_sim
