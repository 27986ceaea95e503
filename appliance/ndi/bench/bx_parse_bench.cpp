// BX parse time for a 6-tool frame (target <= 2 us), plus the full receive path
// (frame reader + parse) and TX text parsing for comparison. Run:
//   build/release/appliance/ndi/ndi_bx_bench --benchmark_format=json
#include <benchmark/benchmark.h>

#include <cmath>

#include "appliance/ndi/bx.hpp"
#include "appliance/ndi/frame_reader.hpp"
#include "appliance/ndi/reply.hpp"

namespace {

using namespace arnav::ndi;

TrackingReply six_tools() {
  TrackingReply t;
  t.count = 6;
  for (std::size_t i = 0; i < 6; ++i) {
    auto& h = t.handles[i];
    h.handle = static_cast<std::uint8_t>(0x0A + i);
    h.state = HandleState::Valid;
    const double a = 0.1 * static_cast<double>(i);
    h.q_NdiTool_wxyz = {std::cos(a), std::sin(a), 0.0, 0.0};
    h.p_NdiTool_mm = {10.0 * static_cast<double>(i), -35.5, -1450.25};
    h.rms_error_mm = 0.12;
    h.has_status = true;
    h.port_status = kPortOccupied | kPortInitialised | kPortEnabled;
    h.frame_number = 123456;
  }
  return t;
}

void BM_ParseBx6Tools(benchmark::State& state) {
  std::vector<std::uint8_t> frame;
  encode_bx(six_tools(), frame);
  TrackingReply out;
  for (auto _ : state) {
    const ParseError e = parse_bx(frame, out);
    benchmark::DoNotOptimize(e);
    benchmark::DoNotOptimize(out.handles[5].p_NdiTool_mm[2]);
  }
  if (parse_bx(frame, out) != ParseError::None || out.count != 6) state.SkipWithError("frame did not parse");
  state.counters["frame_bytes"] = static_cast<double>(frame.size());
}
BENCHMARK(BM_ParseBx6Tools);

void BM_ReaderAndParseBx6Tools(benchmark::State& state) {
  std::vector<std::uint8_t> frame;
  encode_bx(six_tools(), frame);
  FrameReader reader;
  reader.set_expect_binary(true);
  TrackingReply out;
  Frame f;
  for (auto _ : state) {
    reader.feed(frame);
    if (!reader.next(f)) state.SkipWithError("no frame");
    const ParseError e = parse_bx(f.bytes, out, BxCrc::AlreadyChecked);  // as the session does
    benchmark::DoNotOptimize(e);
  }
}
BENCHMARK(BM_ReaderAndParseBx6Tools);

void BM_ParseTx6Tools(benchmark::State& state) {
  const std::string body = format_tx_body(six_tools());
  TrackingReply out;
  for (auto _ : state) {
    const ParseError e = parse_tx(body, out);
    benchmark::DoNotOptimize(e);
  }
}
BENCHMARK(BM_ParseTx6Tools);

}  // namespace

BENCHMARK_MAIN();
