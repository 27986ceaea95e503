#include "host/app/model_input_clock.hpp"

#include <algorithm>
#include <cmath>

namespace arnav::host {
namespace {

std::int64_t floor_to(std::int64_t t, std::int64_t period) {
  const std::int64_t q = t / period;
  return (t % period < 0 ? q - 1 : q) * period;
}

// Inserts keeping the queue ordered by device time (a late sample goes before newer ones).
template <typename Sample>
void insert_ordered(std::deque<Sample>& q, const Sample& s) {
  if (q.empty() || q.back().device_time_us <= s.device_time_us) {
    q.push_back(s);
    return;
  }
  const auto at = std::upper_bound(q.begin(), q.end(), s.device_time_us,
                                   [](std::int64_t t, const Sample& x) { return t < x.device_time_us; });
  q.insert(at, s);
}

}  // namespace

ModelInputClock::ModelInputClock(double rate_hz, double wait_ms, double catch_up_ms, double gap_ms, double cut_catch_up_ms)
    : period_us_(std::max<std::int64_t>(1, std::llround(1e6 / rate_hz))),
      wait_us_(std::llround(wait_ms * 1e3)),
      catch_up_us_(std::llround(catch_up_ms * 1e3)),
      cut_catch_up_us_(std::llround(std::max(cut_catch_up_ms, catch_up_ms) * 1e3)),
      gap_us_(std::llround(gap_ms * 1e3)) {}

void ModelInputClock::note(Stream& s, std::int64_t device_us, std::int64_t host_now_us) {
  if (device_us <= last_taken_us_) ++counters_.late_samples;
  s.last_device_us = std::max(s.last_device_us, device_us);
  s.last_host_us = host_now_us;
  const std::int64_t offset = host_now_us - device_us;
  offset_us_ = offset_us_ ? std::min(*offset_us_, offset) : offset;
  anchor(device_us);
}

void ModelInputClock::anchor(std::int64_t device_us) {
  // The first sample starts the grid: the first step is the grid point at or after it.
  if (!next_us_) next_us_ = floor_to(device_us + period_us_ - 1, period_us_);
}

void ModelInputClock::tracker_at(std::int64_t device_us, std::int64_t host_now_us) {
  tracker_.last_device_us = std::max(tracker_.last_device_us, device_us);
  tracker_.last_host_us = host_now_us;
}

void ModelInputClock::push_blade(const BladeSample& s, std::int64_t host_now_us) {
  note(blade_, s.device_time_us, host_now_us);
  insert_ordered(blades_, s);
}

void ModelInputClock::push_grasp(const GraspSample& s, std::int64_t host_now_us) {
  note(grasp_, s.device_time_us, host_now_us);
  insert_ordered(grasps_, s);
}

std::optional<std::int64_t> ModelInputClock::complete_through(std::int64_t host_now_us, bool& silent) const {
  std::optional<std::int64_t> through;
  silent = false;
  for (const Stream* s : {&blade_, &grasp_}) {
    // A stream that never delivered (a tool the tracker does not report), whose tool the
    // tracker has gone on without, or that has been silent for longer than the wait
    // (tracking lost) is not waited for.
    if (!s->required || s->last_device_us < 0) continue;
    if (host_now_us - s->last_host_us > wait_us_) {
      silent = true;
      continue;
    }
    if (tracker_.last_device_us - s->last_device_us > gap_us_) continue;
    through = through ? std::min(*through, s->last_device_us) : s->last_device_us;
  }
  // Only other tools' poses: the tracker's progress says no sample of ours is coming.
  if (!through && tracker_.last_device_us >= 0 && host_now_us - tracker_.last_host_us <= wait_us_) through = tracker_.last_device_us;
  return through;
}

std::optional<std::int64_t> ModelInputClock::due(std::int64_t host_now_us) {
  if (!next_us_) {
    if (has_inputs()) return std::nullopt;   // the first sample starts the grid
    next_us_ = floor_to(host_now_us, period_us_);  // no inputs: the host clock (offset 0)
  }
  const std::int64_t offset = offset_us_.value_or(0);
  const std::int64_t catch_up = has_inputs() ? catch_up_us_ : period_us_;
  bool silent = false;
  const std::optional<std::int64_t> through = has_inputs() ? complete_through(host_now_us, silent) : std::nullopt;
  std::int64_t t = *next_us_;
  bool ready = through && *through >= t;
  bool waited_out = ready && silent;
  const std::int64_t newest = ready ? *through : host_now_us - offset;  // device time the model could be at
  if (!ready && host_now_us >= t + offset + (has_inputs() ? wait_us_ : 0)) {
    ready = true;
    waited_out = has_inputs();
  }
  if (!ready) return std::nullopt;
  if (waited_out) ++counters_.steps_waited_out;
  if (newest - t > catch_up) {  // too far behind: skip grid steps (the samples stay queued, all applied)
    const std::int64_t to = skip_target(t, newest);
    counters_.steps_skipped += (to - t) / period_us_;
    t = to;
    next_us_ = t;
  }
  return t;
}

std::int64_t ModelInputClock::skip_target(std::int64_t t, std::int64_t newest) {
  const std::int64_t newest_step = floor_to(newest, period_us_);
  const auto cutting = [](const BladeSample& b) { return b.cutting && b.blade_Model_mm.has_value(); };
  if (newest - t <= cut_catch_up_us_) {
    // Not past a cutting sample: the step that takes the first one after t (the samples
    // before it only place the blade).
    for (const BladeSample& b : blades_) {
      if (b.device_time_us <= t || !cutting(b)) continue;
      const std::int64_t its_step = floor_to(b.device_time_us + period_us_ - 1, period_us_);
      if (its_step > t + period_us_) return std::min(newest_step, its_step);
      ++counters_.steps_kept_for_cut;
      return t;
    }
    return newest_step;
  }
  for (const BladeSample& b : blades_)
    if (b.device_time_us > t && b.device_time_us <= newest_step && cutting(b)) ++counters_.cut_samples_merged;
  return newest_step;
}

std::int64_t ModelInputClock::deadline_host_us(std::int64_t host_now_us) const {
  if (!next_us_) return host_now_us + period_us_;
  return *next_us_ + offset_us_.value_or(0) + (has_inputs() ? wait_us_ : 0);
}

ModelStepInputs ModelInputClock::take(std::int64_t t_us, std::int64_t host_now_us) {
  ModelStepInputs in;
  in.device_time_us = t_us;
  while (!blades_.empty() && blades_.front().device_time_us <= t_us) {
    in.blades.push_back(blades_.front());
    blades_.pop_front();
  }
  while (!grasps_.empty() && grasps_.front().device_time_us <= t_us) {
    in.grasp = grasps_.front().command;
    grasps_.pop_front();
  }
  last_taken_us_ = t_us;
  next_us_ = t_us + period_us_;
  ++counters_.steps;
  const double lag_ms = static_cast<double>(host_now_us - (t_us + offset_us_.value_or(0))) * 1e-3;
  counters_.max_lag_ms = std::max(counters_.max_lag_ms, lag_ms);
  return in;
}

}  // namespace arnav::host
