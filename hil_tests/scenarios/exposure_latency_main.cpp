// arnav-exposure-latency: latency from exposure to display by stage, and the dropped frames
// by cause, from a bench run's camera timing file and arnav-host's overlay.csv (and its
// --summary-json); prints JSON. Used by latency_session.sh (docs/benchmarks.md).
// Exit 1 when a check fails (a frame without a timing row, stamps out of order, a frame
// shown that the camera never delivered).
#include <fstream>
#include <iostream>

#include <CLI/CLI.hpp>

#include "hil_tests/scenarios/exposure_latency.hpp"
#include "protocol/guarded_main.hpp"

namespace {
// The first three fields of /proc/loadavg ("" where unreadable).
std::string load_average() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  in >> a >> b >> c;
  return in ? a + " " + b + " " + c : "";
}
}  // namespace

static int main_body(int argc, char** argv) {
  CLI::App app{"arnav-exposure-latency: exposure -> display latency by stage and dropped frames of a bench run (JSON)"};
  arnav::hil::ExposureLatencyInputs in;
  std::string timing, overlay, host_json, load_before;
  app.add_option("--timing", timing, "the synthetic camera's timing file (camera.synthetic.timing)")->required();
  app.add_option("--overlay-csv", overlay, "arnav-host's overlay.csv (--record DIR)")->required();
  app.add_option("--host-json", host_json, "arnav-host's --summary-json (host drop counts)");
  app.add_option("--camera-hz", in.camera_hz, "the camera's frame rate (reported)")->check(CLI::Range(0.0, 1000.0));
  app.add_option("--load-before", load_before, "/proc/loadavg before the run (reported)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  in.timing_csv = timing;
  in.overlay_csv = overlay;
  in.host_json = host_json;
  nlohmann::json j;
  try {
    j = arnav::hil::exposure_latency_report(in);
  } catch (const std::exception& e) {
    std::cerr << "arnav-exposure-latency: " << e.what() << "\n";
    return 2;
  }
  j["load_average"] = {{"before", load_before}, {"after", load_average()}};  // 1, 5, 15 min
  std::cout << j.dump(2) << std::endl;
  const auto& c = j["checks"];
  const bool ok = c["timing_rows_missing"] == 0 && c["timing_rows_duplicated"] == 0 && c["shown_not_delivered"] == 0 &&
                  c["exposure_mismatch"] == 0 && c["stamps_out_of_order"] == 0;
  if (!ok) std::cerr << "arnav-exposure-latency: a check failed (see \"checks\")\n";
  return ok ? 0 : 1;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-exposure-latency", [&] { return main_body(argc, argv); });
}
