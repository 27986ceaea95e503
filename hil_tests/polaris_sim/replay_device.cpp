#include "hil_tests/polaris_sim/replay_device.hpp"

#include <fstream>
#include <iostream>
#include <sstream>

namespace arnav::hil {
namespace {

int hex_digit(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

Bytes unescape(const std::string& s, const std::string& where) {
  Bytes out;
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (s[i] != '\\') {
      out.push_back(static_cast<std::uint8_t>(s[i]));
      continue;
    }
    if (i + 1 < s.size() && s[i + 1] == '\\') {
      out.push_back('\\');
      ++i;
    } else if (i + 3 < s.size() && s[i + 1] == 'x' && hex_digit(s[i + 2]) >= 0 && hex_digit(s[i + 3]) >= 0) {
      out.push_back(static_cast<std::uint8_t>(hex_digit(s[i + 2]) * 16 + hex_digit(s[i + 3])));
      i += 3;
    } else {
      throw ScenarioError(where + ": bad escape at column " + std::to_string(i + 1) + " (expected \\xNN or \\\\)");
    }
  }
  return out;
}

std::string printable(const Bytes& b) {
  std::string s;
  for (std::uint8_t c : b) s += (c >= 32 && c < 127) ? static_cast<char>(c) : '.';
  return s;
}

}  // namespace

Recording parse_igstk_log(const std::string& text, const std::string& source_name) {
  Recording rec;
  rec.source = source_name;
  std::istringstream in(text);
  std::string line;
  int line_no = 0;
  for (; std::getline(in, line); ) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const std::string where = source_name + ":" + std::to_string(line_no);
    const auto info = line.find("(INFO) ");
    if (info == std::string::npos) continue;  // blank, (DEBUG) comments
    const auto dot = line.find(". ", info);
    if (dot == std::string::npos) throw ScenarioError(where + ": expected '(INFO) N. command[len] ...' or 'receive[len]'");
    const std::string rest = line.substr(dot + 2);
    const bool is_command = rest.rfind("command[", 0) == 0;
    const bool is_receive = rest.rfind("receive[", 0) == 0;
    if (!is_command && !is_receive) throw ScenarioError(where + ": expected 'command[len]' or 'receive[len]' after the sequence number");
    const auto close = rest.find(']');
    if (close == std::string::npos || close <= 8) throw ScenarioError(where + ": missing ']' after the length");
    std::size_t len = 0;
    try {
      std::size_t used = 0;
      len = std::stoul(rest.substr(8, close - 8), &used);
      if (used != close - 8) throw std::invalid_argument("len");
    } catch (const std::exception&) {
      throw ScenarioError(where + ": length '" + rest.substr(8, close - 8) + "' is not a number");
    }
    const std::string payload = close + 2 <= rest.size() ? rest.substr(close + 2) : std::string();
    Bytes bytes = unescape(payload, where);
    if (bytes.size() != len)
      throw ScenarioError(where + ": length says " + std::to_string(len) + " bytes but the line holds " + std::to_string(bytes.size()));
    if (is_command) {
      rec.exchanges.push_back(Exchange{std::move(bytes), {}, line_no});
    } else if (!rec.exchanges.empty()) {
      auto& r = rec.exchanges.back().reply;
      r.insert(r.end(), bytes.begin(), bytes.end());  // replies may be logged in pieces
    }
    // A receive before the first command (the power-on RESET) has no command to answer.
  }
  if (rec.exchanges.empty()) throw ScenarioError(source_name + ": no 'command[len]' lines: not an IGSTK serial log");
  return rec;
}

Recording load_replay(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw ScenarioError("cannot read recording " + file.string());
  std::stringstream text;
  text << in.rdbuf();
  return parse_igstk_log(text.str(), file.string());
}

ReplayDevice::ReplayDevice(Recording recording) : recording_(std::move(recording)) {}

Bytes ReplayDevice::reset(double /*now_s*/) {
  baud_ = 9600;
  cursor_ = 0;
  line_.clear();
  return reset_reply();
}

std::vector<PolarisModel::Reply> ReplayDevice::receive(std::span<const std::uint8_t> bytes, double now_s) {
  std::vector<PolarisModel::Reply> out;
  for (std::uint8_t b : bytes) {
    line_.push_back(b);
    if (b != '\r') continue;
    Bytes command;
    command.swap(line_);
    const auto& ex = recording_.exchanges;
    std::size_t found = ex.size();
    for (std::size_t k = 0; k < ex.size() && found == ex.size(); ++k) {
      const std::size_t i = (cursor_ + k) % ex.size();
      if (ex[i].command == command) found = i;
    }
    PolarisModel::Reply r;
    r.command = printable(command);
    if (found == ex.size()) {
      ++unmatched_;
      std::cerr << "arnav-polaris-sim: replay: command '" << r.command << "' is not in " << recording_.source << ": answering ERROR01\n";
      r.bytes = error_reply(0x01);
    } else {
      cursor_ = found + 1;
      r.bytes = ex[found].reply;
      const std::string cmd(command.begin(), command.end());
      const std::string rep(r.bytes.begin(), r.bytes.end());
      if ((cmd.rfind("COMM", 0) == 0) && cmd.size() > 5 && rep.rfind("OKAY", 0) == 0) r.baud_after = comm_code_to_baud(cmd[5]);
      if (cmd.rfind("TSTART", 0) == 0 && !first_tstart_s_) first_tstart_s_ = now_s;
    }
    out.push_back(std::move(r));
    if (line_.size() > 4096) line_.clear();
  }
  if (line_.size() > 4096) line_.clear();
  return out;
}

}  // namespace arnav::hil
