#include "host/app/frame_latency.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <utility>

namespace arnav::host {
namespace {

double ms(std::int64_t from_us, std::int64_t to_us) { return static_cast<double>(to_us - from_us) * 1e-3; }

std::size_t rank(std::size_t n, double q) {
  return std::min(n - 1, static_cast<std::size_t>(q * static_cast<double>(n - 1) + 0.5));
}

nlohmann::json opt(const std::optional<double>& v) { return v ? nlohmann::json(*v) : nlohmann::json(nullptr); }

}  // namespace

std::string stamp_order_error(const FrameStamps& s) {
  const std::array<std::pair<const char*, std::int64_t>, 6> t{{{"exposure", s.exposure_us},
                                                              {"published", s.published_us},
                                                              {"received", s.received_us},
                                                              {"decoded", s.decoded_us},
                                                              {"ready", s.ready_us},
                                                              {"shown", s.shown_us}}};
  for (std::size_t i = 1; i < t.size(); ++i) {
    if (t[i].second < t[i - 1].second) {
      char text[200];
      std::snprintf(text, sizeof text, "frame %lld: %s (%lld us) before %s (%lld us) by %.3f ms", static_cast<long long>(s.sequence),
                    t[i].first, static_cast<long long>(t[i].second), t[i - 1].first, static_cast<long long>(t[i - 1].second),
                    ms(t[i].second, t[i - 1].second));
      return text;
    }
  }
  return "";
}

Quantiles quantiles(std::vector<double> v) {
  Quantiles q;
  if (v.empty()) return q;
  std::sort(v.begin(), v.end());
  q.n = v.size();
  q.p50 = v[rank(v.size(), 0.5)];
  q.p99 = v[rank(v.size(), 0.99)];
  q.p999 = v[rank(v.size(), 0.999)];
  q.max = v.back();
  return q;
}

std::optional<double> quantile_with_misses(std::vector<double> v, std::int64_t misses, double q) {
  const std::size_t total = v.size() + static_cast<std::size_t>(std::max<std::int64_t>(0, misses));
  if (total == 0) return std::nullopt;
  const std::size_t k = rank(total, q);
  if (k >= v.size()) return std::nullopt;
  std::sort(v.begin(), v.end());
  return v[k];
}

nlohmann::json to_json(const Quantiles& q) {
  return {{"n", q.n}, {"p50", q.p50}, {"p99", q.p99}, {"p99_9", q.p999}, {"max", q.max}};
}

void FrameLatency::received(std::int64_t sequence) {
  if (last_received_ >= 0 && sequence > last_received_ + 1) not_received_ += sequence - last_received_ - 1;
  if (sequence > last_received_) last_received_ = sequence;
}

void FrameLatency::shown(const FrameStamps& s) {
  const std::string why = stamp_order_error(s);
  if (!why.empty()) {
    if (out_of_order_ == 0) first_order_error_ = why;
    ++out_of_order_;
  }
  appliance_ms_.push_back(ms(s.exposure_us, s.published_us));
  transport_ms_.push_back(ms(s.published_us, s.received_us));
  decode_ms_.push_back(ms(s.received_us, s.decoded_us));
  render_ms_.push_back(ms(s.decoded_us, s.ready_us));
  display_ms_.push_back(ms(s.ready_us, s.shown_us));
  e2e_ms_.push_back(ms(s.exposure_us, s.shown_us));
  host_ms_.push_back(ms(s.received_us, s.shown_us));
  processing_ms_.push_back(ms(s.received_us, s.ready_us));
}

nlohmann::json FrameLatency::json() const {
  nlohmann::json j;
  j["stages_ms"] = {{"exposure_to_published", to_json(quantiles(appliance_ms_))},
                    {"transport", to_json(quantiles(transport_ms_))},
                    {"decode", to_json(quantiles(decode_ms_))},
                    {"render", to_json(quantiles(render_ms_))},
                    {"display", to_json(quantiles(display_ms_))}};
  j["exposure_to_display_ms"] = to_json(quantiles(e2e_ms_));
  j["exposure_to_display_with_misses_ms"] = {{"p50", opt(quantile_with_misses(e2e_ms_, misses(), 0.5))},
                                             {"p99", opt(quantile_with_misses(e2e_ms_, misses(), 0.99))},
                                             {"p99_9", opt(quantile_with_misses(e2e_ms_, misses(), 0.999))},
                                             {"note", "each missed frame counts as infinitely late; null: the quantile is a miss"}};
  j["received_to_shown_ms"] = to_json(quantiles(host_ms_));
  j["host_processing_latency_ms"] = to_json(quantiles(processing_ms_));
  j["frames_shown"] = frames_shown();
  j["misses"] = {{"total", misses()}, {"dropped_by_host", dropped_by_host_}, {"undecodable", undecodable_}, {"not_received", not_received_}};
  j["stamps_out_of_order"] = out_of_order_;
  if (out_of_order_ > 0) j["first_out_of_order"] = first_order_error_;
  return j;
}

std::string FrameLatency::summary_line() const {
  const Quantiles q = quantiles(e2e_ms_);
  char text[240];
  std::snprintf(text, sizeof text, "exposure-to-display: p50 %.1f ms, p99 %.1f ms, p99.9 %.1f ms (%lld frames shown, %lld missed)", q.p50,
                q.p99, q.p999, static_cast<long long>(frames_shown()), static_cast<long long>(misses()));
  return text;
}

}  // namespace arnav::host
