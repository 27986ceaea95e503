#!/usr/bin/env bash
# Latency from exposure to display on the bench (docs/benchmarks.md "Exposure to display"):
#   latency_session.sh BUILD_DIR OUT_DIR [SECONDS (20)] [CAMERA_HZ (60)] [PHANTOM_TXT]
# Re-executes itself in a private network namespace (root): arnav-host (the AR session of
# ar_demo/session.yaml: the bundled liver, mass-spring model at 60 Hz, registered from
# X_RefModel.yaml, recording on) and arnav-appliance with the synthetic camera alone
# (1280x720, camera.yaml, the reference board 450 mm away, every frame published as JPEG,
# sensor readout one frame period; with PHANTOM_TXT, an arnav-phantom-record recording such
# as ar_session.sh's OUT/phantom.txt, the camera films that deforming phantom too). The
# camera writes OUT/timing.csv (every frame's exposure, rendering, readout end, delivery or
# drop); arnav-exposure-latency joins it with the host's overlay.csv and --summary-json and
# writes OUT/latency.json: p50/p99/p99.9 per stage, exposure -> display, dropped frames by
# cause, the machine's load. Prints (then the drops by cause and the stages):
#   exposure-to-display: p50 P ms, p99 Q ms (camera R Hz), dropped D
# Exit 1 when a check of arnav-exposure-latency fails (stamps out of order, a frame skipped
# without a timing row).
set -euo pipefail
if [ "$#" -lt 2 ]; then
  sed -n '2,15p' "$0" >&2
  exit 2
fi
here=$(cd "$(dirname "$0")" && pwd)
build=$(cd "$1" && pwd)
mkdir -p "$2"
out=$(cd "$2" && pwd)
seconds=${3:-20}
hz=${4:-60}
phantom=${5:-}
host=$build/host/app/arnav-host
appliance=$build/appliance/app/arnav-appliance
report=$build/hil_tests/scenarios/arnav-exposure-latency
for f in "$host" "$appliance" "$report"; do
  [ -x "$f" ] || { echo "latency_session.sh: $f is missing: build first (scripts/build release)" >&2; exit 1; }
done
if [ "${ARNAV_AR_INSIDE:-}" != "1" ]; then
  if [ "$(id -u)" -ne 0 ]; then
    echo "latency_session.sh: needs root for a private network namespace (run with sudo)" >&2
    exit 1
  fi
  if [ -n "$phantom" ]; then
    [ -s "$phantom" ] || { echo "latency_session.sh: phantom recording $phantom not found (ar_session.sh writes OUT/phantom.txt)" >&2; exit 2; }
    phantom=$(cd "$(dirname "$phantom")" && pwd)/$(basename "$phantom")
  fi
  export ARNAV_AR_INSIDE=1
  exec unshare --net "$0" "$build" "$out" "$seconds" "$hz" "$phantom"
fi
command -v python3 >/dev/null || { echo "latency_session.sh: python3 missing" >&2; exit 1; }
. "$here/ar_bench.sh"
ar_bus_up
frames=$(python3 -c "import sys; print(int(round(float(sys.argv[1]) * float(sys.argv[2]))))" "$seconds" "$hz")
cp "$here"/ar_demo/{camera.yaml,marker_board.yaml,X_RefModel.yaml,X_RefModel_phantom.yaml} "$out/"
registration=X_RefModel.yaml
phantom_line=""
if [ -n "$phantom" ]; then
  registration=X_RefModel_phantom.yaml
  phantom_line="    phantom: {recording: $phantom, board: liver_marker, X_BoardModel: X_RefModel_phantom.yaml, reflectance: 0.6}"
fi
# The host: the AR session without the tracked scalpel (no Polaris in this run).
sed -e "s#^scene: [^ ]*#scene: $here/ar_demo/liver_navigation.scene.yaml#" -e "s#^registration: .*#registration: $registration#" \
  -e '/^  scalpel:/d' "$here/ar_demo/session.yaml" >"$out/session.yaml"
cat >"$out/appliance.yaml" <<EOF
# latency_session.sh: the synthetic camera alone, every frame published (docs/benchmarks.md).
lcm_url: "udpm://239.255.76.67:7667?ttl=0"
security: off  # bench bus, not sealed
camera:
  name: bench
  source: synthetic
  fps: $hz
  intrinsics: camera.yaml
  retry_interval_s: 0.2
  detector: {family: tag36h11, decimate: 2, threads: 1}
  publish_frames: {every: 1, jpeg_quality: 80}
  tools:
    - name: liver_marker
      board: marker_board.yaml
  synthetic:
    frames: $frames
    timing: timing.csv       # every frame: exposure, rendering, readout end, delivery or drop
    noise_sigma: 1.5
    blur_sigma_px: 0.5
    boards:
      - tool: liver_marker
        trajectory: {distance_mm: 450, amplitude_mm: [0, 0, 0], offset_mm: [105, 0], period_s: 10, tilt_deg: 0, spin_deg: 0}
$phantom_line
EOF
load_before=$(cut -d' ' -f1-3 /proc/loadavg)
pids=()
trap ar_stop_pids EXIT
ar_start_host "$host" >/dev/null
(cd "$out" && exec "$appliance" appliance.yaml 2>"$out/appliance.log" >/dev/null) &
app_pid=$!
pids+=("$app_pid")
limit=$(python3 -c "import sys; print(int(float(sys.argv[1]) * 10) + 600)" "$seconds")
ar_finish "$app_pid" "$limit"
trap - EXIT
[ "$app_rc" -eq 0 ] || { echo "latency_session.sh: arnav-appliance exited $app_rc:" >&2; tail -20 "$out/appliance.log" >&2; exit 1; }
rc=0
"$report" --timing "$out/timing.csv" --overlay-csv "$out/recording/overlay.csv" --host-json "$out/host.json" --camera-hz "$hz" \
  --load-before "$load_before" >"$out/latency.json" || rc=$?
[ "$rc" -le 1 ] || { echo "latency_session.sh: arnav-exposure-latency failed (exit $rc)" >&2; exit "$rc"; }
python3 - "$out/latency.json" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
e, d = j["exposure_to_display_ms"], j["dropped"]
f, s, w = j["frames"], j["stages_ms"], j["exposure_to_display_without_bench_render_late_ms"]
print("exposure-to-display: p50 %.1f ms, p99 %.1f ms (camera %g Hz), dropped %d" % (e["p50"], e["p99"], j["camera_hz"], d["total"]))
print("  %d frames exposed, %d shown; dropped: bench renderer late %d, appliance late %d, host %d, lost after delivery %d"
      % (f["exposed"], f["shown"], d["camera_render_late"], d["camera_reader_late"], d["host_dropped"] + d["host_undecodable"],
         d["lost_after_delivery"]))
print("  stages p50/p99 ms: readout %.1f/%.1f, bench render late %.1f/%.1f, appliance %.1f/%.1f, transport %.1f/%.1f, decode %.1f/%.1f, render %.1f/%.1f, display %.1f/%.1f"
      % tuple(x for k in ("readout (modelled)", "bench_render_late", "appliance (delivered->published)", "transport", "decode", "render", "display")
              for x in (s[k]["p50"], s[k]["p99"])))
b = j["bench_renderer"]
print("  the bench's renderer (on the same CPUs; a real camera costs them nothing): %d frames rendered, %.1f ms wall each, busy %.0f %% of the run"
      % (b["frames_rendered"], b["wall_ms_per_frame"], 100 * b["busy_fraction_of_run"]))
print("  without the bench renderer's lateness: p50 %.1f ms, p99 %.1f ms; host processing latency p50 %.1f ms, p99 %.1f ms; load average %s -> %s"
      % (w["p50"], w["p99"], s["host_processing_latency"]["p50"], s["host_processing_latency"]["p99"], j["load_average"]["before"],
         j["load_average"]["after"]))
PY
exit "$rc"
