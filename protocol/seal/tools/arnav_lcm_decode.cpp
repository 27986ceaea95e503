// arnav-lcm-decode LOG (--key FILE | --security off) [--limit N] [--dropped-only]
// Shows an lcm-logger log of the (sealed) bus, one line per message: receive time,
// channel, verdict, sender and counter (sealed), size and the message's gist (ARNav types).
// Then one summary line. Exit 0 read, 1 nothing in the log could be opened (why, and what
// to do), 2 usage, log or key problems.
#include <CLI/CLI.hpp>
#include <lcm/lcm-cpp.hpp>

#include <cstdio>
#include <iostream>
#include <sstream>

#include "arnav/appliance_event_t.hpp"
#include "arnav/device_health_t.hpp"
#include "arnav/image_frame_t.hpp"
#include "arnav/input_event_t.hpp"
#include "arnav/point_cloud_t.hpp"
#include "arnav/tool_pose_t.hpp"
#include "protocol/channels.hpp"
#include "protocol/guarded_main.hpp"
#include "protocol/seal/log_opener.hpp"

namespace {

bool starts(const std::string& s, std::string_view p) { return s.compare(0, p.size(), p) == 0; }

template <class Msg>
bool decode(std::span<const std::uint8_t> b, Msg& m) {
  return m.decode(b.data(), 0, static_cast<int>(b.size())) == static_cast<int>(b.size());
}

// A short description of an ARNav message (or its size when the channel is not ours).
std::string gist(const std::string& ch, std::span<const std::uint8_t> b) {
  std::ostringstream s;
  s.precision(1);
  s << std::fixed;
  if (starts(ch, arnav::channels::kPosePrefix)) {
    arnav::tool_pose_t m;
    if (!decode(b, m)) return "undecodable tool_pose_t";
    s << "tool_pose_t " << m.tool_name << " X_" << m.frame_parent << m.frame_child << " status " << int(m.status) << " p_mm (" << m.p_ParentChild_mm[0]
      << ", " << m.p_ParentChild_mm[1] << ", " << m.p_ParentChild_mm[2] << ") seq " << m.sequence;
  } else if (ch == arnav::channels::kInput || ch == arnav::channels::kInputState) {
    arnav::input_event_t m;
    if (!decode(b, m)) return "undecodable input_event_t";
    s << "input_event_t " << m.input_name << (m.state == arnav::input_event_t::STATE_PRESSED ? " pressed" : " released") << " cause " << int(m.cause)
      << " seq " << m.sequence;
  } else if (starts(ch, arnav::channels::kFramePrefix)) {
    arnav::image_frame_t m;
    if (!decode(b, m)) return "undecodable image_frame_t";
    s << "image_frame_t " << m.camera_name << " " << m.width << "x" << m.height << " " << m.size << " bytes seq " << m.sequence;
  } else if (starts(ch, arnav::channels::kHealthPrefix)) {
    arnav::device_health_t m;
    if (!decode(b, m)) return "undecodable device_health_t";
    s << "device_health_t " << m.device << " link " << int(m.link_state) << " " << m.frame_rate_hz << " Hz: " << m.detail;
  } else if (ch == arnav::channels::kEvents) {
    arnav::appliance_event_t m;
    if (!decode(b, m)) return "undecodable appliance_event_t";
    s << "appliance_event_t " << m.source << " " << m.code << ": " << m.text;
  } else if (starts(ch, arnav::channels::kCloudPrefix)) {
    arnav::point_cloud_t m;
    if (!decode(b, m)) return "undecodable point_cloud_t";
    s << "point_cloud_t " << m.num_points << " points";
  } else {
    s << b.size() << " bytes";
  }
  return s.str();
}

std::string hex(const arnav::seal::SenderId& id) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%02x%02x%02x%02x%02x%02x%02x%02x", id[0], id[1], id[2], id[3], id[4], id[5], id[6], id[7]);
  return buf;
}

}  // namespace

static int main_body(int argc, char** argv) {
  CLI::App cli{"arnav-lcm-decode: show the messages of an lcm-logger log of the ARNav bus, sealed or not (docs/protocol.md)"};
  std::string log_path, key_file, security;
  long long limit = -1;
  bool dropped_only = false;
  cli.add_option("log", log_path, "lcm-logger file")->required();
  cli.add_option("--key", key_file, "the bus key the log was sealed with (arnav-keygen)");
  cli.add_option("--security", security, "'off': the log is not sealed (old logs, bench buses)");
  cli.add_option("--limit", limit, "print at most this many message lines (the summary counts all)");
  cli.add_flag("--dropped-only", dropped_only, "print only the messages that do not open");
  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return cli.exit(e) == 0 ? 0 : 2;
  }
  arnav::seal::BusSecurity sec;
  try {
    sec = arnav::seal::security_from_cli(key_file, security, "arnav-lcm-decode");
  } catch (const arnav::seal::SecurityError& e) {
    std::cerr << e.what() << "\n";
    return 2;
  }
  lcm::LogFile log(log_path, "r");
  if (!log.good()) {
    std::cerr << "arnav-lcm-decode: " << log_path << ": cannot open the log (an lcm-logger file)\n";
    return 2;
  }
  std::cout << "arnav-lcm-decode: " << log_path << ": " << sec.describe() << "\n";
  arnav::seal::LogOpener opener(sec);
  long long printed = 0, events = 0, self_tests = 0;
  while (const lcm::LogEvent* ev = log.readNextEvent()) {
    if (ev->channel == "LCM_SELF_TEST") {  // LCM's own start-up check (udpm): not a message of the bus's programs
      ++self_tests;
      continue;
    }
    ++events;
    const auto plain = opener.open(*ev);
    const bool accepted = plain.has_value();
    if ((dropped_only && accepted) || (limit >= 0 && printed >= limit)) continue;
    ++printed;
    std::cout << ev->timestamp << " " << ev->channel << " " << arnav::seal::to_string(opener.last_verdict());
    if (sec.sealed() && opener.opener() && opener.last_verdict() != arnav::seal::Verdict::Unsealed &&
        opener.last_verdict() != arnav::seal::Verdict::Malformed) {
      const auto& h = opener.opener()->last_header();
      std::cout << " sender " << hex(h.sender) << " #" << h.counter;
    }
    std::cout << " " << ev->datalen << " B";
    if (accepted) std::cout << ": " << gist(ev->channel, *plain);
    std::cout << "\n";
  }
  std::cout << "arnav-lcm-decode: " << events << " messages (" << self_tests << " LCM self-test messages skipped): ";
  if (sec.sealed()) std::cout << arnav::seal::format_counters(opener.counters()) << "\n";
  else std::cout << opener.counters().accepted << " read, " << opener.sealed_without_key() << " sealed (no key given)\n";
  if (const std::string p = opener.problem(log_path); !p.empty() && events > 0) {
    std::cerr << "arnav-lcm-decode: " << p << "\n";
    return 1;
  }
  return 0;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-lcm-decode", [&] { return main_body(argc, argv); });
}
