#pragma once
// Replay mode: the simulator acts out a recorded session. Each command the host sends is
// looked up in the recording (forward from the last match, then from the start, so a
// recorded tracking loop can be replayed for longer than it was recorded) and answered
// with the recorded reply. A command the recording never saw gets ERROR01, and the
// simulator says which command it was.
#include <filesystem>
#include <string>
#include <vector>

#include "appliance/ndi/transcript.hpp"
#include "hil_tests/polaris_sim/sim_device.hpp"

namespace arnav::hil {

struct Exchange {
  Bytes command;  // with its CR
  Bytes reply;    // everything the device sent back
  int line = 0;   // where it was in the file, for messages
};

struct Recording {
  std::string source;
  std::vector<Exchange> exchanges;
};

// Pairs the commands of a transcript (appliance/ndi/transcript.hpp) with the replies
// that followed them; baud, break and note records carry no device bytes.
Recording recording_from_transcript(const std::vector<ndi::TranscriptRecord>& records, const std::string& source_name);
// Loads an `arnav-ndi record` transcript, or an IGSTK serial log (imported by the NDI
// driver's reader). Throws ScenarioError naming the file (and line) on bad input.
Recording load_replay(const std::filesystem::path& file);

class ReplayDevice : public SimDevice {
 public:
  explicit ReplayDevice(Recording recording);
  std::vector<PolarisModel::Reply> receive(std::span<const std::uint8_t> bytes, double now_s) override;
  Bytes reset(double now_s) override;
  int baud() const override { return baud_; }
  void set_baud(int baud) override { baud_ = baud; }
  std::optional<double> first_tstart_s() const override { return first_tstart_s_; }
  std::size_t unmatched() const { return unmatched_; }

 private:
  Recording recording_;
  std::size_t cursor_ = 0;
  Bytes line_;
  int baud_ = 9600;
  std::optional<double> first_tstart_s_;
  std::size_t unmatched_ = 0;
};

}  // namespace arnav::hil
