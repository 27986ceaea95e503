#include "host/app/security_alarm.hpp"

#include <algorithm>
#include <cstdio>
#include <iterator>

namespace arnav::host {

namespace {

constexpr std::size_t kMaxChannels = 256;  // channel names remembered (an attacker may invent any number)

seal::OpenCounters minus(const seal::OpenCounters& a, const seal::OpenCounters& b) {
  seal::OpenCounters d;
  d.accepted = a.accepted - b.accepted;
  d.unsealed = a.unsealed - b.unsealed;
  d.malformed = a.malformed - b.malformed;
  d.forged = a.forged - b.forged;
  d.tampered = a.tampered - b.tampered;
  d.replayed = a.replayed - b.replayed;
  d.stale = a.stale - b.stale;
  return d;
}

std::string hold_text(std::int64_t hold_us) {
  char s[32];
  std::snprintf(s, sizeof s, "%g s", static_cast<double>(hold_us) * 1e-6);
  return s;
}

}  // namespace

SecurityAlarm::SecurityAlarm(SecurityAlarmOptions options) : options_(options) {
  if (options_.max_entries < 2) options_.max_entries = 2;
}

std::uint32_t SecurityAlarm::channel_id(const std::string& channel) {
  if (const auto it = ids_.find(channel); it != ids_.end()) return it->second;
  if (channels_.size() + 1 >= kMaxChannels) {
    // Every further channel under one name (an attacker may invent any number of them).
    static const std::string kOther = "(one of many channels)";
    if (const auto it = ids_.find(kOther); it != ids_.end()) return it->second;
    channels_.push_back(kOther);
    ids_.emplace(kOther, static_cast<std::uint32_t>(channels_.size()));
    return static_cast<std::uint32_t>(channels_.size());
  }
  channels_.push_back(channel);
  ids_.emplace(channel, static_cast<std::uint32_t>(channels_.size()));
  return static_cast<std::uint32_t>(channels_.size());
}

bool SecurityAlarm::on_drop(seal::Verdict verdict, const std::string& channel, std::int64_t now_us) {
  if (verdict == seal::Verdict::Accepted) return false;
  const bool onset = entries_.empty() || entries_.back().t_us <= now_us - options_.hold_us;
  Entry e;
  if (!entries_.empty()) e = entries_.back();
  e.t_us = std::max(now_us, entries_.empty() ? now_us : entries_.back().t_us);  // receive order
  e.running.add(verdict);
  total_.add(verdict);
  if (verdict == seal::Verdict::Unsealed) e.last_unsealed = channel_id(channel);
  else e.last_rejected = channel_id(channel);
  entries_.push_back(e);
  // Forget what no frame can ask for any more (a frame is never more than a hold behind
  // the newest drop), and bound the memory under a flood.
  while (entries_.size() > options_.max_entries ||
         (entries_.size() > 1 && entries_.front().t_us < e.t_us - 2 * options_.hold_us)) {
    base_ = entries_.front().running;
    entries_.pop_front();
  }
  return onset;
}

SecurityWindow SecurityAlarm::window_at(std::int64_t now_us) const {
  SecurityWindow w;
  const auto after = [](std::int64_t t, const Entry& e) { return t < e.t_us; };
  const auto hi = std::upper_bound(entries_.begin(), entries_.end(), now_us, after);
  if (hi == entries_.begin()) return w;  // nothing received by now_us
  const Entry& last = *std::prev(hi);
  const auto lo = std::upper_bound(entries_.begin(), entries_.end(), now_us - options_.hold_us, after);
  const seal::OpenCounters before = lo == entries_.begin() ? base_ : std::prev(lo)->running;
  w.dropped = minus(last.running, before);
  if (w.sealed_rejected() > 0 && last.last_rejected > 0) w.last_rejected_channel = channels_[last.last_rejected - 1];
  if (w.dropped.unsealed > 0 && last.last_unsealed > 0) w.last_unsealed_channel = channels_[last.last_unsealed - 1];
  return w;
}

std::vector<std::string> SecurityAlarm::banners_at(std::int64_t now_us) const {
  std::vector<std::string> out;
  const SecurityWindow w = window_at(now_us);
  const std::string hold = hold_text(options_.hold_us);
  if (w.sealed_rejected() > 0) {
    std::string text = "SECURITY: bus messages rejected (last " + hold + "):";
    const std::pair<const char*, std::uint64_t> kinds[] = {{"forged", w.dropped.forged},     {"tampered", w.dropped.tampered},
                                                           {"replayed", w.dropped.replayed}, {"stale", w.dropped.stale},
                                                           {"malformed", w.dropped.malformed}};
    const char* sep = " ";
    for (const auto& [name, n] : kinds) {
      if (n == 0) continue;
      text += sep + std::string(name) + " " + std::to_string(n);
      sep = ", ";
    }
    out.push_back(text);
  }
  if (w.dropped.unsealed > 0)
    out.push_back("SECURITY: unsealed messages on the sealed bus (last " + hold + "): " + std::to_string(w.dropped.unsealed) + ", last on " +
                  w.last_unsealed_channel);
  return out;
}

}  // namespace arnav::host
