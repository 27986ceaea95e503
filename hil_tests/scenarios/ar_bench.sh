# Sourced by ar_session.sh and ar_phantom_session.sh (docs/hil.md): the steps every AR
# session on the bench shares, run inside the private network namespace. Uses and sets
# the caller's variables: out (run folder), pids (processes to stop on exit).

# Loopback up with a multicast route: LCM's udpm stays inside this namespace.
ar_bus_up() {
  ip link set lo up
  ip route add 224.0.0.0/4 dev lo
  ar_url="udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304"
}

ar_stop_pids() { for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done; }

# The sealed bus (docs/security.md): a fresh session key for this run in OUT/bus.key, made by
# arnav-keygen ($1), readable by its owner only; the run's session.yaml and appliance.yaml
# name it (security: {key_file: bus.key}).
ar_make_key() {
  rm -f "$out/bus.key"
  "$1" "$out/bus.key" | sed 's/^/  /'
}

# arnav-bus-attacker ($1; hil_tests/attacker) on the bus without the key: once it has
# captured the first sealed messages, ARNAV_AR_ATTACK_HZ (default 200) injections a second
# until ar_finish stops it: forged poses of the board ($2) and the scalpel, cut-pedal presses
# and frames of camera $3 (plain, and sealed with its own key), replays of the session's own
# sealed traffic and bit-flipped or re-channelled copies of it. Report: OUT/attack.json (sets
# attacker_pid).
ar_start_attacker() {
  "$1" --lcm-url "$ar_url" --tool "$2" --camera "$3" --rate "${ARNAV_AR_ATTACK_HZ:-200}" --count 100000000 --duration 3600 \
    --wait-capture 30 --report "$out/attack.json" >"$out/attacker.log" 2>&1 &
  attacker_pid=$!
  pids+=("$attacker_pid")
}

# The security line from the host's counters (security_report.py, next to this file);
# returns 3 when an injected message was accepted, 2 when there is nothing to report.
ar_print_security() {
  echo "== security: sealed bus under attack (arnav-host's counters; docs/security.md) =="
  python3 "$(dirname "${BASH_SOURCE[0]}")/security_report.py" "$out/host.json" "$out/appliance.log" "$out/attack.json"
}

# lcm-logger records the bus into OUT/session.lcmlog (sets logger_pid).
ar_start_logger() {
  lcm-logger --lcm-url="$ar_url" -f "$out/session.lcmlog" >"$out/logger.log" 2>&1 &
  logger_pid=$!
  pids+=("$logger_pid")
}

# arnav-host OUT/session.yaml, recording into OUT/recording; returns once it says
# "session ready" (sets host_pid; exits 1 with its log if it fails or is not ready in 60 s).
ar_start_host() {
  "$1" "$out/session.yaml" --record "$out/recording" --quiet --summary --summary-json "$out/host.json" >"$out/host.log" 2>&1 &
  host_pid=$!
  pids+=("$host_pid")
  for _ in $(seq 1 600); do
    grep -q "session ready" "$out/host.log" 2>/dev/null && break
    kill -0 "$host_pid" 2>/dev/null || { echo "arnav-host failed:" >&2; cat "$out/host.log" >&2; exit 1; }
    sleep 0.1
  done
  grep "session ready" "$out/host.log" || { echo "arnav-host not ready after 60 s" >&2; exit 1; }
}

# Waits until the appliance (pid $1) reports its camera's last frame (at most $2 tenths of
# a second), stops the bus attacker if one runs (attacker_pid), then the appliance, the host
# and the logger if one runs (sets app_rc, the appliance's exit code).
ar_finish() {
  local app_pid=$1 limit=$2
  for _ in $(seq 1 "$limit"); do
    grep -q "CAMERA_END" "$out/appliance.log" 2>/dev/null && break
    kill -0 "$app_pid" 2>/dev/null || break
    sleep 0.1
  done
  # The bus attacker (ar_session.sh) stops first: the host counts all it sent.
  if [ -n "${attacker_pid:-}" ]; then
    kill -TERM "$attacker_pid" 2>/dev/null || true
    wait "$attacker_pid" || true
  fi
  sleep 1
  kill -TERM "$app_pid" 2>/dev/null || true
  app_rc=0
  wait "$app_pid" || app_rc=$?
  kill -TERM "$host_pid"
  wait "$host_pid" || true
  if [ -n "${logger_pid:-}" ]; then
    kill -TERM "$logger_pid"
    wait "$logger_pid" || true
  fi
}

# The host's own summary block.
ar_print_host_summary() {
  echo "== arnav-host =="
  sed -n '/^navigation:/,$p' "$out/host.log" | grep -v "^recorded" | sed 's/^/  /'
}

# The bench's world clock: a CLOCK_MONOTONIC epoch (us) now, written into the simulated
# Polaris' scenario (epoch_mono_us: the tools' motions) and the synthetic camera's phantom
# (phantom.epoch_mono_us: the filmed tissue), and given to arnav-can-sim (--epoch-mono-us:
# the pedal's steps), so every simulated device plays the same world time however late each
# starts (docs/hil.md). The world's time 0 is ARNAV_AR_WORLD_LEAD_S (default 5 s) from now:
# the appliance, the simulated Polaris and the camera come up meanwhile (each loads the
# phantom recording first). Sets ar_epoch_us; $1: the Polaris scenario, $2: the appliance config.
ar_world_clock() {
  ar_epoch_us=$(python3 -c 'import sys, time; print(time.clock_gettime_ns(time.CLOCK_MONOTONIC) // 1000 + round(float(sys.argv[1]) * 1e6))' \
    "${ARNAV_AR_WORLD_LEAD_S:-5}")
  printf 'epoch_mono_us: %s   # the bench world clock (ar_bench.sh ar_world_clock)\n' "$ar_epoch_us" >>"$1"
  sed -i "s#^\(    phantom: {recording: [^}]*\)}#\1, epoch_mono_us: $ar_epoch_us}#" "$2"
  grep -q "epoch_mono_us: $ar_epoch_us" "$2" || { echo "ar_bench.sh: no 'phantom: {recording: ...}' line in $2 to put the world clock in" >&2; exit 1; }
}
