#!/usr/bin/env bash
# One session on the HIL bench, by hand or from scripts/demo and soak.sh:
#   bench_session.sh BUILD_DIR SIM_SCENARIO.yaml APPLIANCE.yaml SECONDS OUT_DIR [RSS_EVERY_S]
# Re-executes itself inside private mount + network namespaces (root): the simulated
# Polaris is bind-mounted over /dev/ttyS0 there, arnav-appliance opens it through
# libserialport with the test-only serial shim preloaded, arnav-host prints status, and
# LCM udpm stays on the namespace's loopback. Writes logs, the simulator's events and the
# host's JSON summary to OUT_DIR; with RSS_EVERY_S it samples the appliance's resident
# memory into OUT_DIR/appliance_rss.csv. Environment: ARNAV_SIM_PRIORITY (see below);
# ARNAV_BENCH_KEY=FILE: the bus is sealed with this key (the appliance's config must name it,
# security: {key_file: ...}; arnav-host gets --key FILE), else the host runs --security off.
set -euo pipefail
if [ "$#" -lt 5 ]; then
  sed -n '2,13p' "$0" >&2
  exit 2
fi
if [ "${ARNAV_BENCH_INSIDE:-}" != "1" ]; then
  if [ "$(id -u)" -ne 0 ]; then
    echo "bench_session.sh: needs root for private mount and network namespaces (run with sudo)" >&2
    exit 1
  fi
  export ARNAV_BENCH_INSIDE=1
  exec unshare --mount --net --propagation private "$0" "$@"
fi

build=$(cd "$1" && pwd)
sim_cfg=$2
app_cfg=$3
seconds=$4
out=$5
rss_every=${6:-0}
mkdir -p "$out"
out=$(cd "$out" && pwd)

sim=$build/hil_tests/polaris_sim/arnav-polaris-sim
shim=$build/hil_tests/interposer/libarnav_hil_serial_shim.so
appliance=${ARNAV_APPLIANCE_EXE:-$build/appliance/app/arnav-appliance}
host=$build/host/app/arnav-host
for f in "$sim" "$shim" "$appliance" "$host"; do
  [ -e "$f" ] || { echo "bench_session.sh: $f is missing: build first (scripts/build release)" >&2; exit 1; }
done
[ -e /sys/class/tty/ttyS0 ] && [ -e /dev/ttyS0 ] || {
  echo "bench_session.sh: no /dev/ttyS0 with a sysfs entry here: nothing to bind the simulated port over" >&2
  exit 1
}

# Loopback only; multicast to lo. Nothing leaves this namespace.
ip link set lo up
ip route add 224.0.0.0/4 dev lo
lcm_url="udpm://239.255.76.67:7667?ttl=0"

pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
}
trap cleanup EXIT

# ARNAV_SIM_PRIORITY=N runs the simulator under SCHED_FIFO N: a real Polaris keeps its
# own time, a normally scheduled simulator on a loaded machine answers late.
# (With sudo, put it after sudo: `sudo ARNAV_SIM_PRIORITY=60 ...`; sudo drops the caller's
# environment.) Where SCHED_FIFO is refused, the simulator runs normally and says so.
sim_prefix=()
sim_sched="normal scheduling"
if [ "${ARNAV_SIM_PRIORITY:-0}" != "0" ]; then
  if chrt --fifo "$ARNAV_SIM_PRIORITY" true 2>/dev/null; then
    sim_prefix=(chrt --fifo "$ARNAV_SIM_PRIORITY")
    sim_sched="SCHED_FIFO $ARNAV_SIM_PRIORITY"
  else
    sim_sched="normal scheduling (SCHED_FIFO $ARNAV_SIM_PRIORITY refused here: no CAP_SYS_NICE or no real-time budget)"
  fi
fi
"${sim_prefix[@]}" "$sim" --pty-link "$out/polaris" --bind-over /dev/ttyS0 --break-socket "$out/break.sock" --control "$out/control.sock" \
  --events "$out/sim_events.jsonl" --scenario "$sim_cfg" >"$out/sim.stdout" 2>"$out/sim.log" &
sim_pid=$!
pids+=("$sim_pid")
for _ in $(seq 1 300); do
  grep -q '^READY ' "$out/sim.stdout" 2>/dev/null && break
  kill -0 "$sim_pid" 2>/dev/null || { echo "simulator failed:" >&2; cat "$out/sim.log" >&2; exit 1; }
  sleep 0.1
done
grep -q '^READY ' "$out/sim.stdout" || { echo "simulator not ready after 30 s" >&2; exit 1; }
echo "simulated Polaris: $(cat "$out/sim.stdout") bound over /dev/ttyS0 (scenario $sim_cfg, $sim_sched)"

LD_PRELOAD=$shim ARNAV_HIL_BREAK_SOCKET=$out/break.sock "$appliance" "$app_cfg" 2>"$out/appliance.log" &
app_pid=$!
pids+=("$app_pid")
echo "arnav-appliance: pid $app_pid, config $app_cfg (log $out/appliance.log)"

if [ "$rss_every" != "0" ]; then
  (
    echo "t_s,rss_kib"
    start=$(date +%s)
    while kill -0 "$app_pid" 2>/dev/null; do
      rss=$(awk '/^VmRSS:/ {print $2}' "/proc/$app_pid/status" 2>/dev/null || true)
      [ -n "$rss" ] && echo "$(($(date +%s) - start)),$rss"
      sleep "$rss_every"
    done
  ) >"$out/appliance_rss.csv" &
  pids+=("$!")
fi

period=5
[ "$seconds" -gt 120 ] && period=60
host_security=(--security off)
[ -n "${ARNAV_BENCH_KEY:-}" ] && host_security=(--key "$ARNAV_BENCH_KEY")
"$host" --lcm-url "$lcm_url" "${host_security[@]}" --duration "$seconds" --print-period "$period" --stale-after-ms 250 --summary \
  --summary-json "$out/host.json" | tee "$out/host.log"

kill -TERM "$app_pid"
app_rc=0
wait "$app_pid" || app_rc=$?
kill -TERM "$sim_pid"
wait "$sim_pid" || true
trap - EXIT
echo "== simulator: faults injected and link events =="
grep -E "fault|port_gone|port_back|device_reset|break|reset_sent" "$out/sim.log" | grep -v "stopped:" | sed 's/^arnav-polaris-sim: /  /' || echo "  none"
grep "stopped:" "$out/sim.log" | sed 's/^arnav-polaris-sim: /  /' || true
echo "== appliance: exit code $app_rc (0 = clean shutdown: TSTOP, COMM back to 9600) =="
grep -E "NDI_TRACKING_STOPPED|NDI_STOP_FAILED" "$out/appliance.log" | sed 's/^/  /' || true
if [ -s "$out/appliance_rss.csv" ]; then
  echo "== appliance resident memory (KiB): first, at 60 s, last, max =="
  awk -F, 'NR > 1 { if (first == "") first = $2; if ($1 >= 60 && at60 == "") at60 = $2; last = $2; if ($2 > max) max = $2 }
           END { printf "  %s, %s, %s, %s\n", first, at60, last, max }' "$out/appliance_rss.csv"
fi
exit "$app_rc"
