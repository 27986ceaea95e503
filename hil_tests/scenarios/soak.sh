#!/usr/bin/env bash
# Soak (by hand, not in CI; needs root and ~10 quiet minutes):
#   hil_tests/scenarios/soak.sh [SECONDS=600] [BUILD_DIR=build/release] [RATE_HZ=400]
# 6 tools at RATE_HZ (default 400, the Vega XT rate) on the simulated Polaris for SECONDS; passes when no tool lost or
# repeated a device frame (arnav-host's continuity counters and the appliance's
# dropped_frames), the appliance shut down cleanly, and its resident memory did not grow
# after the first minute by more than 1 MiB.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
seconds=${1:-600}
build=${2:-$here/../../build/release}
rate=${3:-400}
out=$(mktemp -d /tmp/arnav-soak-XXXXXX)
echo "soak: ${seconds} s, 6 tools at ${rate} Hz; output in $out"
# The configs with the rate set and the ROM paths made absolute (they move to $out).
data=$(cd "$here/../../data" && pwd)
sed -e "s|^frame_rate_hz: .*|frame_rate_hz: ${rate}|" -e "s|\.\./\.\./data|${data}|" "$here/soak_sim.yaml" >"$out/soak_sim.yaml"
sed -e "s|^rate_hz: .*|rate_hz: ${rate}|" -e "s|\.\./\.\./data|${data}|" "$here/soak_appliance.yaml" >"$out/soak_appliance.yaml"
# The appliance runs its polling thread SCHED_FIFO (soak_appliance.yaml, realtime:); the
# simulator, standing in for the device's own clock, runs SCHED_FIFO too.
session_rc=0
ARNAV_SIM_PRIORITY=${ARNAV_SIM_PRIORITY:-60} "$here/bench_session.sh" "$build" "$out/soak_sim.yaml" "$out/soak_appliance.yaml" "$seconds" "$out" 10 ||
  session_rc=$?
# The verdict is printed whatever happened above (missing lines count as failures).
echo "== soak verdict =="
grep -E '^tool [^ ]+ +[0-9]+ valid' "$out/host.log" 2>/dev/null || echo "no per-tool summary in $out/host.log"
bad=$(grep -cE "^tool .* ([1-9][0-9]*) duplicate frames|, ([1-9][0-9]*) frame gaps|STALE at exit" "$out/host.log" 2>/dev/null || true)
dropped=$( (grep -oE "dropped frames [0-9]+" "$out/host.log" 2>/dev/null || true) | tail -1 | awk '{print $3}')
growth=$(awk -F, 'NR > 1 { if ($1 >= 60 && at60 == "") at60 = $2; last = $2 } END { print (at60 == "" ? 0 : last - at60) }' "$out/appliance_rss.csv" 2>/dev/null || echo 0)
echo "session exit code: $session_rc; tools with lost/repeated frames: ${bad:-?}; appliance dropped_frames: ${dropped:-?}; RSS growth after 60 s: ${growth} KiB"
if [ "$session_rc" = "0" ] && [ "${bad:-1}" = "0" ] && [ "${dropped:-1}" = "0" ] && [ "$growth" -le 1024 ]; then
  echo "SOAK PASSED"
else
  echo "SOAK FAILED"
  exit 1
fi
