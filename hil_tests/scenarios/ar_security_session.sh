#!/usr/bin/env bash
# The sealed-bus steps of scripts/demo's AR session on their own, in a short session:
#   ar_security_session.sh BUILD_DIR OUT_DIR [FRAMES]
# the same ar_bench.sh steps ar_session.sh runs (ar_make_key: a fresh key by arnav-keygen;
# lcm-logger; arnav-host sealed; ar_start_attacker: arnav-bus-attacker without the key;
# ar_finish: the attacker stopped before the host; ar_print_security: the `security:` line
# from the host's counters) around arnav-appliance's synthetic camera filming the AR demo's
# static board (FRAMES at 15 Hz, default 90: 6 s), no Polaris, no CAN, no phantom. Then the
# session's log is replayed with the key (the attacks dropped again). Re-executes itself in
# a private network namespace (root). Exit 0 when the line says 0 accepted; 3 when an
# injected message was accepted; 1 when a step failed; 77 without root (test skipped).
# Used by hil_ar_security_session_test (docs/hil.md, docs/security.md).
set -euo pipefail
if [ "$#" -lt 2 ]; then
  sed -n '2,12p' "$0" >&2
  exit 2
fi
here=$(cd "$(dirname "$0")" && pwd)
build=$(cd "$1" && pwd)
mkdir -p "$2"
out=$(cd "$2" && pwd)
frames=${3:-90}
host=$build/host/app/arnav-host
appliance=$build/appliance/app/arnav-appliance
keygen=$build/protocol/seal/arnav-keygen
attacker=$build/hil_tests/attacker/arnav-bus-attacker
for f in "$host" "$appliance" "$keygen" "$attacker"; do
  [ -x "$f" ] || { echo "ar_security_session.sh: $f is missing: build first (scripts/build release)" >&2; exit 1; }
done
if [ "${ARNAV_AR_INSIDE:-}" != "1" ]; then
  if [ "$(id -u)" -ne 0 ] || ! unshare --net true 2>/dev/null; then
    echo "ar_security_session.sh: needs root and network namespaces (unshare --net): skipped" >&2
    exit 77
  fi
  export ARNAV_AR_INSIDE=1
  exec unshare --net "$0" "$@"
fi
command -v lcm-logger >/dev/null || { echo "ar_security_session.sh: lcm-logger missing (Debian liblcm-bin, scripts/deps)" >&2; exit 1; }
. "$here/ar_bench.sh"
ar_bus_up
cp "$here"/ar_demo/{camera.yaml,marker_board.yaml} "$out/"
cp "$here/ar_demo/X_RefModel_phantom.yaml" "$out/X_RefModel.yaml"
sed -e "s#^scene: [^ ]*#scene: $here/ar_demo/liver_navigation.scene.yaml#" -e "s#^security: .*#security: {key_file: bus.key}#" \
  "$here/ar_demo/session.yaml" >"$out/session.yaml"
cat >"$out/appliance.yaml" <<EOF
lcm_url: "$ar_url"
security: {key_file: bus.key}
camera:
  name: bench
  source: synthetic
  fps: 15
  intrinsics: camera.yaml
  detector: {family: tag36h11, decimate: 2, threads: 1}
  publish_frames: {every: 1, jpeg_quality: 80}
  tools:
    - name: liver_marker
      board: marker_board.yaml
  synthetic:
    frames: $frames
    ground_truth: ground_truth.csv
    noise_sigma: 1.5
    blur_sigma_px: 0.5
    boards:
      - tool: liver_marker
        trajectory: {distance_mm: 450, amplitude_mm: [0, 0, 0], offset_mm: [105, 0], period_s: 10, tilt_deg: 0, spin_deg: 0}
EOF
ar_make_key "$keygen"
pids=()
trap ar_stop_pids EXIT
ar_start_logger
ar_start_host "$host"
(cd "$out" && exec "$appliance" appliance.yaml 2>"$out/appliance.log") &
app_pid=$!
pids+=("$app_pid")
ar_start_attacker "$attacker" liver_marker bench
ar_finish "$app_pid" 600
trap - EXIT
sec_rc=0
ar_print_security || sec_rc=$?
# The log holds the sealed bytes, attacks included: the replay with the key drops them again.
"$host" "$out/session.yaml" --replay "$out/session.lcmlog" --replay-speed 0 --quiet --summary-json "$out/replay.json" >"$out/replay.log" 2>&1 ||
  { echo "ar_security_session.sh: the replay failed:" >&2; cat "$out/replay.log" >&2; exit 1; }
python3 - "$out/replay.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))["security"]
print("  replay of the session's log with the key: %d dropped again (forged %d, replayed %d, tampered %d, unsealed %d), %d accepted"
      % (s["dropped"], s["forged"], s["replayed"], s["tampered"], s["unsealed"], s["accepted"]))
PY
[ "$sec_rc" -eq 0 ] || exit "$sec_rc"
[ "$app_rc" -eq 0 ] || { echo "ar_security_session.sh: arnav-appliance exited $app_rc:" >&2; tail -20 "$out/appliance.log" >&2; exit 1; }
