#!/usr/bin/env bash
# The AR navigation session against the deforming phantom (docs/hil.md, "Deforming phantom"):
#   ar_phantom_session.sh BUILD_DIR OUT_DIR [FRAMES]
# 1. arnav-phantom-record runs the reference deformation (ar_demo/phantom_reference.scene.yaml:
#    finer mesh, co-rotational FEM, heterogeneous material; a grasper pulls the underside of
#    the liver twice, from 3 s on: the grasper first rests on the tissue while the bench's
#    processes come up, so the host sees the grasp start) and writes OUT/phantom.txt (deterministic; about 1-2 min, 20 MB, not
#    committed). An existing OUT/phantom.txt is reused. It also runs the host's scene under
#    the same grasp (--compare-scene): how close the host's model would be if it coupled
#    the tool, next to a rigid model.
# 2. Re-executes itself in a private network namespace (root): lcm-logger, arnav-host
#    ar_demo/session_phantom.yaml (mass-spring model, registered to the phantom's board),
#    arnav-appliance ar_demo/appliance_phantom.yaml (synthetic camera filming the deforming
#    phantom; simulated Polaris moving the grasper along the recorded tool path).
# 3. arnav-ar-error: the overlay's tumour centroid against the deformed ground truth, and what
#    a rigid overlay would score. FRAMES: camera frames at 15 Hz (default 255, 17 s).
set -euo pipefail
if [ "$#" -lt 2 ]; then
  sed -n '2,17p' "$0" >&2
  exit 2
fi
here=$(cd "$(dirname "$0")" && pwd)
build=$(cd "$1" && pwd)
mkdir -p "$2"
out=$(cd "$2" && pwd)
frames=${3:-255}
host=$build/host/app/arnav-host
appliance=$build/appliance/app/arnav-appliance
ar_error=$build/hil_tests/scenarios/arnav-ar-error
record=$build/hil_tests/phantom/arnav-phantom-record
for f in "$host" "$appliance" "$ar_error" "$record"; do
  [ -x "$f" ] || { echo "ar_phantom_session.sh: $f is missing: build first (scripts/build release)" >&2; exit 1; }
done
if [ "${ARNAV_AR_INSIDE:-}" != "1" ]; then
  if [ "$(id -u)" -ne 0 ]; then
    echo "ar_phantom_session.sh: needs root for a private network namespace (run with sudo)" >&2
    exit 1
  fi
  if [ ! -s "$out/phantom.txt" ]; then
    duration=$(python3 -c "print(round($frames / 15.0, 3))" 2>/dev/null || echo 17)
    echo "arnav-phantom-record: reference deformation, ${duration} s at 10 Hz (co-rotational FEM, fine mesh)"
    "$record" --scene "$here/ar_demo/phantom_reference.scene.yaml" --out "$out/phantom.txt" --fps 10 --duration "$duration" \
      --pull 20 10 -15 --grasp-radius 15 --start 3 --quiet --compare-scene "$here/ar_demo/liver_navigation.scene.yaml" >"$out/phantom_record.json"
    python3 - "$out/phantom_record.json" <<'PY' || cat "$out/phantom_record.json"
import json, sys
j = json.load(open(sys.argv[1]))
print("  reference: %s, %d vertices / %d tets, median step %.0f ms; surface moved up to %.1f mm, tumour up to %.1f mm"
      % (j["model"], j["volume_vertices"], j["volume_tets"], j["median_step_ms"], j["max_surface_displacement_mm"], j["max_tumour_displacement_mm"]))
c = j["compare"]
m, r = c["model_vs_reference_mm"], c["rigid_vs_reference_mm"]
print("  the host's scene (%s) under the same grasp: tumour centroid off the reference by mean %.2f, p95 %.2f, max %.2f mm"
      % (c["model"], m["mean"], m["p95"], m["max"]))
print("  a rigid model: mean %.2f, p95 %.2f, max %.2f mm (what an overlay that ignores the grasp is off by, before projection)"
      % (r["mean"], r["p95"], r["max"]))
PY
  fi
  export ARNAV_AR_INSIDE=1
  exec unshare --net "$0" "$@"
fi
command -v lcm-logger >/dev/null || { echo "ar_phantom_session.sh: lcm-logger missing (Debian liblcm-bin, scripts/deps)" >&2; exit 1; }
. "$here/ar_bench.sh"
ar_bus_up
data=$(cd "$here/../../data" && pwd)
cp "$here"/ar_demo/{camera.yaml,marker_board.yaml,X_RefModel_phantom.yaml,X_CamNdi.yaml} "$out/"
sed "s#^scene: [^ ]*#scene: $here/ar_demo/liver_navigation.scene.yaml#" "$here/ar_demo/session_phantom.yaml" >"$out/session.yaml"
sed -e "s#\.\./\.\./\.\./data/#$data/#" -e "s#^    frames: 255#    frames: $frames#" "$here/ar_demo/appliance_phantom.yaml" >"$out/appliance.yaml"
# Sensors (docs/hil.md "Sensor errors"): realistic, seed ARNAV_SEED (default 1); ARNAV_SENSORS=ideal for the exact poses.
sed -e "s#\.\./\.\./\.\./data/#$data/#" \
  -e "s#^measurement: {model: realistic,\(.*\) seed: 1}#measurement: {model: ${ARNAV_SENSORS:-realistic},\1 seed: ${ARNAV_SEED:-1}}#" \
  "$here/ar_demo/polaris_phantom.yaml" >"$out/polaris_phantom.yaml"

pids=()
trap ar_stop_pids EXIT
ar_start_logger
ar_start_host "$host"
# The camera's phantom and the simulated Polaris' grasper on one world clock from now on.
ar_world_clock "$out/polaris_phantom.yaml" "$out/appliance.yaml"
echo "arnav-appliance: synthetic camera filming the deforming phantom, $frames frames at 15 Hz; simulated Polaris moving the grasper with the phantom's tool"
(cd "$out" && exec "$appliance" appliance.yaml 2>"$out/appliance.log") &
app_pid=$!
pids+=("$app_pid")
ar_finish "$app_pid" 3000
trap - EXIT
ar_print_host_summary
echo "== AR error against the deforming phantom (arnav-ar-error) =="
"$ar_error" --session "$out/session.yaml" --ground-truth "$out/ground_truth.csv" --overlay-csv "$out/recording/overlay.csv" \
  | tee "$out/ar_error.json" | python3 -c '
import json, sys
j = json.load(sys.stdin)
e, p = j["ar_error_mm"], j["ar_error_px"]
print("  truth: %s" % j["truth"])
print("  frames with overlay: %d of %d displayed (%d made by the camera)" % (j["frames_evaluated"], j["csv_rows"], j["truth_frames"]))
print("  host overlay:  mean %.2f mm, p95 %.2f mm, max %.2f mm; mean %.2f px, p95 %.2f px, max %.2f px"
      % (e["mean"], e["p95"], e["max"], p["mean"], p["p95"], p["max"]))
if "rigid_overlay" in j:
    r, rp, d = j["rigid_overlay"]["ar_error_mm"], j["rigid_overlay"]["ar_error_px"], j["tumour_displacement_mm"]
    print("  rigid overlay: mean %.2f mm, p95 %.2f mm, max %.2f mm; mean %.2f px, p95 %.2f px, max %.2f px"
          % (r["mean"], r["p95"], r["max"], rp["mean"], rp["p95"], rp["max"]))
    print("  tumour displacement (deformed vs rest, 3D): mean %.2f mm, max %.2f mm" % (d["mean"], d["max"]))
' || echo "  (python3 missing: see $out/ar_error.json)"
# The same session replayed from its LCM log (deterministic, as fast as possible): the host's
# chain without this machine's load, scored against the same truth (docs/hil.md).
"$host" "$out/session.yaml" --replay "$out/session.lcmlog" --replay-speed 0 --quiet --record "$out/replay" \
  --summary-json "$out/replay.json" >"$out/replay.log" 2>&1 || echo "  (replay failed: $out/replay.log)"
"$ar_error" --session "$out/session.yaml" --ground-truth "$out/ground_truth.csv" --overlay-csv "$out/replay/overlay.csv" \
  >"$out/ar_error_replay.json" 2>>"$out/replay.log" && python3 -c '
import json, sys
j = json.load(open(sys.argv[1]))
e, p = j["ar_error_mm"], j["ar_error_px"]
print("  replay of the log: mean %.2f mm, p95 %.2f mm, max %.2f mm; mean %.2f px, p95 %.2f px, max %.2f px (%d frames)"
      % (e["mean"], e["p95"], e["max"], p["mean"], p["p95"], p["max"], j["frames_evaluated"]))
' "$out/ar_error_replay.json" || true
echo "== files =="
echo "  phantom:       $out/phantom.txt"
echo "  ground truth:  $out/ground_truth.csv"
echo "  video:         $out/recording/overlay.avi"
echo "  contact sheet: $out/recording/contact_sheet.png"
exit "$app_rc"
