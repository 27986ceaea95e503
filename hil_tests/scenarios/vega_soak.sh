#!/usr/bin/env bash
# Vega soak (docs/hil.md, docs/benchmarks.md): the simulated Polaris Vega streaming BX2 at
# 400 Hz with 6 tools over TCP into the real arnav-appliance, in the bench's private
# network namespace (needs root), for SECONDS (a person runs 600; the HIL test a few).
#   hil_tests/scenarios/vega_soak.sh BUILD_DIR OUT_DIR SECONDS
# Prints the JSON summary and one line "vega soak: F frames, L lost, p99 latency X us"
# (device timestamp -> published); exit 0 when nothing was lost or repeated, every pose
# was valid and the appliance stopped cleanly. The simulator runs SCHED_FIFO
# ARNAV_SIM_PRIORITY (default 60, as soak.sh; 0: normal scheduling), standing in for a
# device that keeps its own clock; with sudo write `sudo ARNAV_SIM_PRIORITY=0 ...`.
set -euo pipefail
if [ $# -ne 3 ]; then
  echo "usage: $0 BUILD_DIR OUT_DIR SECONDS" >&2
  exit 2
fi
build=$1
out=$2
seconds=$3
exe="$build/hil_tests/scenarios/arnav-hil-vega-soak"
if [ ! -x "$exe" ]; then
  echo "vega_soak.sh: $exe is not built (cmake --build $build -t arnav-hil-vega-soak arnav-vega-sim arnav-appliance)" >&2
  exit 2
fi
mkdir -p "$out"
echo "vega soak: ${seconds} s, 6 tools at 400 Hz over TCP, simulator SCHED_FIFO ${ARNAV_SIM_PRIORITY:-60}; load before: $(cut -d' ' -f1-3 /proc/loadavg); output in $out"
rc=0
"$exe" --seconds "$seconds" --out "$out" --rate 400 --tools 6 --sim-priority "${ARNAV_SIM_PRIORITY:-60}" >"$out/vega_soak.out" 2>"$out/vega_soak.err" || rc=$?
cat "$out/vega_soak.out"
echo "load after: $(cut -d' ' -f1-3 /proc/loadavg)"
if [ "$rc" != 0 ]; then
  tail -n 20 "$out/vega_soak.err" >&2
  echo "VEGA SOAK FAILED (exit $rc)"
  exit 1
fi
echo "VEGA SOAK PASSED"
