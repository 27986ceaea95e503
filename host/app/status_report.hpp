#pragma once
// What arnav-host prints: the periodic status table and the end-of-run summary.
#include <cstdint>
#include <string>

#include "host/app/tool_freshness.hpp"

namespace arnav::host {

// One row per tool (fresh/stale, status, rate, age, frame, gaps), then one per device.
std::string format_status_table(const ToolFreshnessTracker& tracker, std::int64_t now_us);
// Rates, continuity, outages, device counters, latency and the events seen (faults and
// recoveries), for a run of run_s seconds.
std::string format_summary(const ToolFreshnessTracker& tracker, double run_s);

}  // namespace arnav::host
