#pragma once
// arnav-host started by an end-to-end test on DIR/session.yaml: summary JSON DIR/host.json,
// log DIR/host.log, stdout read for its "session ready" line.
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "hil_tests/bench/child_process.hpp"
#include "protocol/testing/child_process.hpp"

namespace arnav::hil {

// Starts the host and waits up to 600 s for "session ready"; false when it exits or does not
// get there (its log says why: host->log_tail()).
inline bool start_host(const std::filesystem::path& dir, std::unique_ptr<ChildProcess>& host) {
  host = std::make_unique<ChildProcess>(
      std::vector<std::string>{arnav::testing::binary_path("host/app/arnav-host"), (dir / "session.yaml").string(), "--quiet",
                               "--summary", "--summary-json", (dir / "host.json").string()},
      std::vector<std::string>{}, (dir / "host.log").string(), true);
  for (int i = 0; i < 600; ++i) {
    const auto line = host->read_line(1.0);
    if (line && line->find("session ready") != std::string::npos) return true;
    if (!line && !host->running()) return false;
  }
  return false;
}

}  // namespace arnav::hil
