#include "hil_tests/scenarios/exposure_latency.hpp"

#include <algorithm>
#include <array>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "appliance/capture/synthetic_source.hpp"
#include "host/app/frame_latency.hpp"

namespace arnav::hil {
namespace {

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  for (std::string c; std::getline(ss, c, ',');) out.push_back(c);
  if (!line.empty() && line.back() == ',') out.emplace_back();
  return out;
}

std::int64_t integer(const std::string& text, const std::string& where) {
  try {
    std::size_t used = 0;
    const long long v = std::stoll(text, &used);
    if (used != text.size()) throw std::invalid_argument(text);
    return v;
  } catch (const std::exception&) {
    throw std::runtime_error(where + ": '" + text + "' is not an integer");
  }
}

struct TimingRow {
  std::int64_t exposure = 0, render_start = -1, render_done = -1, readout_end = 0, delivered = -1;
  std::string status;
};

std::map<std::int64_t, TimingRow> read_timing(const std::filesystem::path& path, std::int64_t* duplicates) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path.string() + ": cannot read the camera's timing file (camera.synthetic.timing)");
  std::string line;
  std::getline(in, line);
  if (line != capture::kTimingCsvHeader)
    throw std::runtime_error(path.string() + ":1: not a synthetic camera timing file (expected the header '" +
                             std::string(capture::kTimingCsvHeader) + "')");
  std::map<std::int64_t, TimingRow> rows;
  for (int line_no = 2; std::getline(in, line); ++line_no) {
    const std::string where = path.string() + ":" + std::to_string(line_no);
    const auto c = split(line);
    if (c.size() != 8) throw std::runtime_error(where + ": expected 8 columns, got " + std::to_string(c.size()));
    TimingRow r{integer(c[1], where), integer(c[2], where), integer(c[3], where), integer(c[4], where), integer(c[5], where), c[7]};
    if (r.status != "delivered" && r.status != "dropped_render_late" && r.status != "dropped_reader_late" && r.status != "absent")
      throw std::runtime_error(where + ": unknown status '" + r.status + "'");
    if (!rows.emplace(integer(c[0], where), r).second) ++*duplicates;
  }
  return rows;
}

struct ShownRow {
  std::int64_t exposure = 0, published = 0, received = 0, decoded = 0, ready = 0, shown = 0;
};

std::map<std::int64_t, ShownRow> read_overlay(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path.string() + ": cannot read arnav-host's overlay.csv (--record DIR)");
  std::string line;
  std::getline(in, line);
  const auto header = split(line);
  const auto col = [&](const char* name) {
    for (std::size_t i = 0; i < header.size(); ++i)
      if (header[i] == name) return i;
    throw std::runtime_error(path.string() + ":1: no column '" + name + "' (an overlay.csv from an arnav-host without the frame instants)");
  };
  const std::array<std::size_t, 7> idx{col("camera_sequence"), col("capture_time_mono_us"), col("publish_time_mono_us"),
                                       col("receive_time_mono_us"), col("decode_done_mono_us"), col("render_done_mono_us"),
                                       col("shown_mono_us")};
  std::map<std::int64_t, ShownRow> rows;
  for (int line_no = 2; std::getline(in, line); ++line_no) {
    const std::string where = path.string() + ":" + std::to_string(line_no);
    const auto c = split(line);
    if (c.size() != header.size()) throw std::runtime_error(where + ": " + std::to_string(c.size()) + " columns, the header has " + std::to_string(header.size()));
    rows[integer(c[idx[0]], where)] = {integer(c[idx[1]], where), integer(c[idx[2]], where), integer(c[idx[3]], where),
                                       integer(c[idx[4]], where), integer(c[idx[5]], where), integer(c[idx[6]], where)};
  }
  return rows;
}

double ms(std::int64_t a, std::int64_t b) { return static_cast<double>(b - a) * 1e-3; }

}  // namespace

nlohmann::json exposure_latency_report(const ExposureLatencyInputs& in) {
  std::int64_t duplicates = 0;
  const auto timing = read_timing(in.timing_csv, &duplicates);
  const auto shown = read_overlay(in.overlay_csv);
  if (timing.empty()) throw std::runtime_error(in.timing_csv.string() + ": no frame (did the camera run?)");

  std::int64_t missing_rows = 0, exposed = 0, delivered = 0, absent = 0, render_late = 0, reader_late = 0, delivered_late = 0;
  // The bench renderer's own time (wall, on the machine the product runs on): its load is not
  // a real camera's.
  std::int64_t rendered = 0, render_wall_us = 0;
  for (const auto& [seq, r] : timing)
    if (r.render_start >= 0 && r.render_done >= r.render_start) {
      ++rendered;
      render_wall_us += r.render_done - r.render_start;
    }
  for (std::int64_t k = timing.begin()->first; k <= timing.rbegin()->first; ++k) {
    const auto it = timing.find(k);
    if (it == timing.end()) {
      ++missing_rows;
      continue;
    }
    const TimingRow& r = it->second;
    if (r.status == "absent") {
      ++absent;
      continue;
    }
    ++exposed;
    if (r.status == "delivered") {
      ++delivered;
      delivered_late += r.delivered > r.readout_end;
    }
    render_late += r.status == "dropped_render_late";
    reader_late += r.status == "dropped_reader_late";
  }

  std::map<std::string, std::vector<double>> st;
  std::int64_t out_of_order = 0, shown_not_delivered = 0, exposure_mismatch = 0, shown_count = 0;
  std::string first_out_of_order;
  for (const auto& [seq, s] : shown) {
    const auto it = timing.find(seq);
    if (it == timing.end() || it->second.status != "delivered") {
      ++shown_not_delivered;
      continue;
    }
    ++shown_count;
    const TimingRow& t = it->second;
    if (s.exposure != t.exposure) ++exposure_mismatch;
    const std::array<std::pair<const char*, std::int64_t>, 8> chain{{{"exposure", t.exposure},
                                                                    {"readout_end", t.readout_end},
                                                                    {"delivered", t.delivered},
                                                                    {"published", s.published},
                                                                    {"received", s.received},
                                                                    {"decoded", s.decoded},
                                                                    {"ready", s.ready},
                                                                    {"shown", s.shown}}};
    for (std::size_t i = 1; i < chain.size(); ++i)
      if (chain[i].second < chain[i - 1].second) {
        if (out_of_order++ == 0) {
          char text[200];
          std::snprintf(text, sizeof text, "frame %lld: %s %.3f ms before %s", static_cast<long long>(seq), chain[i].first,
                        ms(chain[i].second, chain[i - 1].second), chain[i - 1].first);
          first_out_of_order = text;
        }
        break;
      }
    const double bench_late = ms(t.readout_end, t.delivered);
    st["readout (modelled)"].push_back(ms(t.exposure, t.readout_end));
    st["bench_render_late"].push_back(bench_late);
    st["appliance (delivered->published)"].push_back(ms(t.delivered, s.published));
    st["exposure_to_published"].push_back(ms(t.exposure, s.published));
    st["transport"].push_back(ms(s.published, s.received));
    st["decode"].push_back(ms(s.received, s.decoded));
    st["render"].push_back(ms(s.decoded, s.ready));
    st["display"].push_back(ms(s.ready, s.shown));
    st["host (received->shown)"].push_back(ms(s.received, s.shown));
    st["host_processing_latency"].push_back(ms(s.received, s.ready));
    st["e2e"].push_back(ms(t.exposure, s.shown));
    st["e2e_without_bench"].push_back(ms(t.exposure, s.shown) - bench_late);
  }

  const std::int64_t dropped = exposed - shown_count;
  nlohmann::json j;
  j["camera_hz"] = in.camera_hz;
  nlohmann::json stages = nlohmann::json::object();
  for (const char* name : {"readout (modelled)", "bench_render_late", "appliance (delivered->published)", "exposure_to_published",
                           "transport", "decode", "render", "display", "host (received->shown)", "host_processing_latency"})
    stages[name] = host::to_json(host::quantiles(st[name]));
  j["stages_ms"] = stages;
  j["exposure_to_display_ms"] = host::to_json(host::quantiles(st["e2e"]));
  j["exposure_to_display_without_bench_render_late_ms"] = host::to_json(host::quantiles(st["e2e_without_bench"]));
  const auto opt = [](const std::optional<double>& v) { return v ? nlohmann::json(*v) : nlohmann::json(nullptr); };
  j["exposure_to_display_with_misses_ms"] = {{"p50", opt(host::quantile_with_misses(st["e2e"], dropped, 0.5))},
                                             {"p99", opt(host::quantile_with_misses(st["e2e"], dropped, 0.99))},
                                             {"p99_9", opt(host::quantile_with_misses(st["e2e"], dropped, 0.999))},
                                             {"note", "each dropped frame counts as infinitely late; null: the quantile is a miss"}};
  const double run_us = static_cast<double>(std::max<std::int64_t>(1, timing.rbegin()->second.readout_end - timing.begin()->second.exposure));
  j["bench_renderer"] = {{"frames_rendered", rendered},
                         {"wall_ms_per_frame", rendered > 0 ? static_cast<double>(render_wall_us) * 1e-3 / static_cast<double>(rendered) : 0.0},
                         {"busy_fraction_of_run", static_cast<double>(render_wall_us) / run_us},
                         {"note", "the synthetic camera's renderer runs on the product's CPUs; a real camera costs them nothing"}};
  j["frames"] = {{"first_sequence", timing.begin()->first},
                 {"last_sequence", timing.rbegin()->first},
                 {"exposed", exposed},
                 {"delivered", delivered},
                 {"delivered_after_readout_end", delivered_late},
                 {"shown", shown_count},
                 {"absent_camera_unplugged", absent}};
  nlohmann::json d = {{"total", dropped},
                      {"fraction", exposed > 0 ? static_cast<double>(dropped) / static_cast<double>(exposed) : 0.0},
                      {"camera_render_late", render_late},
                      {"camera_reader_late", reader_late}};
  const std::int64_t not_shown_after_delivery = delivered - shown_count;
  if (!in.host_json.empty()) {
    std::ifstream hj(in.host_json);
    if (!hj) throw std::runtime_error(in.host_json.string() + ": cannot read arnav-host's --summary-json");
    nlohmann::json h;
    try {
      h = nlohmann::json::parse(hj);
    } catch (const nlohmann::json::exception& e) {
      throw std::runtime_error(in.host_json.string() + ": not JSON: " + e.what());
    }
    const nlohmann::json& nav = h.contains("navigation") ? h["navigation"] : h;
    if (!nav.contains("latency")) throw std::runtime_error(in.host_json.string() + ": no navigation.latency (an arnav-host without it)");
    const auto& m = nav["latency"]["misses"];
    const std::int64_t host_dropped = m["dropped_by_host"].get<std::int64_t>(), undecodable = m["undecodable"].get<std::int64_t>();
    d["host_dropped"] = host_dropped;
    d["host_undecodable"] = undecodable;
    d["lost_after_delivery"] = not_shown_after_delivery - host_dropped - undecodable;
  } else {
    d["delivered_not_shown"] = not_shown_after_delivery;
  }
  j["dropped"] = d;
  j["checks"] = {{"timing_rows_missing", missing_rows},
                 {"timing_rows_duplicated", duplicates},
                 {"shown_not_delivered", shown_not_delivered},
                 {"exposure_mismatch", exposure_mismatch},
                 {"stamps_out_of_order", out_of_order}};
  if (out_of_order > 0) j["checks"]["first_out_of_order"] = first_out_of_order;
  return j;
}

}  // namespace arnav::hil
