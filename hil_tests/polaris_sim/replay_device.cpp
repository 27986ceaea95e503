#include "hil_tests/polaris_sim/replay_device.hpp"

#include <fstream>

#include "appliance/ndi/command.hpp"
#include <iostream>

namespace arnav::hil {
namespace {

std::string printable(const Bytes& b) {
  std::string s;
  for (std::uint8_t c : b) s += (c >= 32 && c < 127) ? static_cast<char>(c) : '.';
  return s;
}

}  // namespace

Recording recording_from_transcript(const std::vector<ndi::TranscriptRecord>& records, const std::string& source_name) {
  using Kind = ndi::TranscriptRecord::Kind;
  Recording rec;
  rec.source = source_name;
  for (const auto& r : records) {
    if (r.kind == Kind::Command) {
      rec.exchanges.push_back(Exchange{Bytes(r.bytes.begin(), r.bytes.end()), {}, r.line});
    } else if (r.kind == Kind::Reply && !rec.exchanges.empty()) {
      // Replies may be logged in pieces; a reply before the first command (the power-on
      // RESET) answers nothing.
      auto& reply = rec.exchanges.back().reply;
      reply.insert(reply.end(), r.bytes.begin(), r.bytes.end());
    }
  }
  if (rec.exchanges.empty()) throw ScenarioError(source_name + ": the recording holds no commands: nothing to replay");
  return rec;
}

Recording load_replay(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw ScenarioError("cannot read recording " + file.string());
  std::string first;
  std::getline(in, first);
  in.clear();
  in.seekg(0);
  try {
    const bool transcript = first.rfind(std::string(ndi::kTranscriptHeader), 0) == 0;
    return recording_from_transcript(transcript ? ndi::read_transcript(in, file.string()) : ndi::import_igstk_log(in, file.string()),
                                     file.string());
  } catch (const ndi::TranscriptError& e) {
    throw ScenarioError(std::string(e.what()) + " (expected an arnav-ndi transcript or an IGSTK serial log)");
  }
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
      if ((cmd.rfind("COMM", 0) == 0) && cmd.size() > 5 && rep.rfind("OKAY", 0) == 0) r.baud_after = ndi::baud_from_code(cmd[5]).value_or(0);
      if (cmd.rfind("TSTART", 0) == 0 && !first_tstart_s_) first_tstart_s_ = now_s;
    }
    out.push_back(std::move(r));
    if (line_.size() > 4096) line_.clear();
  }
  if (line_.size() > 4096) line_.clear();
  return out;
}

}  // namespace arnav::hil
