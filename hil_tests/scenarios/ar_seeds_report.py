#!/usr/bin/env python3
"""AR error over several seeded AR sessions (scripts/demo --seeds N, docs/hil.md "Sensor errors"):

  ar_seeds_report.py --out DIR RUN_DIR...

Each RUN_DIR is an ar_session.sh run folder (ar_error.json, ar_error_frames.csv, its seed and
sensors in sensors.txt). Prints

  AR error 3-D (tumour centroid, N seeds): mean X mm, p95 Y mm, max Z mm
  availability: A % of frames with the board visible after registration

over the frames of all seeds together (each frame one sample), then per seed and the mean
+- sd of the per-seed means; writes DIR/seeds.json and DIR/seeds.csv (one row per seed).
"""
import argparse
import csv
import json
import math
import os
import sys


def fail(msg):
    print("ar_seeds_report.py: " + msg, file=sys.stderr)
    sys.exit(2)


def quantile(v, q):
    if not v:
        return float("nan")
    v = sorted(v)
    return v[min(len(v) - 1, int(q * (len(v) - 1) + 0.5))]


def read_run(d):
    try:
        j = json.load(open(os.path.join(d, "ar_error.json")))
        rows = list(csv.DictReader(open(os.path.join(d, "ar_error_frames.csv"))))
        info = dict(line.strip().split("=", 1) for line in open(os.path.join(d, "sensors.txt")) if "=" in line)
    except (OSError, ValueError) as e:
        fail(f"{d}: not a complete ar_session.sh run ({e})")
    if "ar_error_3d_mm" not in j:
        fail(f"{d}/ar_error.json: no 3-D error (an overlay.csv without tumour_x/y/z_cam_mm)")
    e3 = [float(r["error_3d_mm"]) for r in rows if r["error_3d_mm"]]
    return {"dir": d, "seed": info.get("seed", "?"), "sensors": info.get("sensors", "?"), "e3": e3, "json": j}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("runs", nargs="+")
    a = ap.parse_args()
    runs = [read_run(d) for d in a.runs]
    sensors = sorted({r["sensors"] for r in runs})
    if len(sensors) != 1:
        fail("the runs mix sensor models %s: compare them separately" % sensors)
    pooled = [x for r in runs for x in r["e3"]]
    eligible = sum(r["json"]["availability"]["eligible_frames"] for r in runs)
    shown = sum(r["json"]["availability"]["with_overlay"] for r in runs)
    means = [sum(r["e3"]) / len(r["e3"]) if r["e3"] else float("nan") for r in runs]
    mean_of_means = sum(means) / len(means)
    sd = math.sqrt(sum((m - mean_of_means) ** 2 for m in means) / (len(means) - 1)) if len(means) > 1 else 0.0
    label = "" if sensors[0] == "realistic" else " [IDEAL sensors: exact poses and landmarks]"
    n = len(runs)
    print("AR error 3-D (tumour centroid, %d seeds): mean %.2f mm, p95 %.2f mm, max %.2f mm%s"
          % (n, sum(pooled) / len(pooled) if pooled else float("nan"), quantile(pooled, 0.95), max(pooled) if pooled else float("nan"), label))
    print("availability: %.1f %% of frames with the board visible after registration (%d of %d, %d seeds)%s"
          % (100.0 * shown / eligible if eligible else 0.0, shown, eligible, n, label))
    print("  per-seed mean %.2f +- %.2f mm (sd over %d seeds)" % (mean_of_means, sd, n))
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.out, "seeds.csv"), "w") as f:
        f.write("seed,sensors,frames,mean_3d_mm,p95_3d_mm,max_3d_mm,availability_percent,eligible_frames,fre_mm,run_dir\n")
        for r, m in zip(runs, means):
            av = r["json"]["availability"]
            fre = r.get("fre", "")
            try:
                nav = json.load(open(os.path.join(r["dir"], "host.json")))["navigation"]["registration"]
                fre = "%.3f" % nav["fre_mm"]
            except (OSError, KeyError, ValueError):
                pass
            f.write("%s,%s,%d,%.3f,%.3f,%.3f,%.2f,%d,%s,%s\n" % (r["seed"], r["sensors"], len(r["e3"]), m, quantile(r["e3"], 0.95),
                                                             max(r["e3"]) if r["e3"] else float("nan"), av["percent"], av["eligible_frames"], fre, r["dir"]))
            print("  seed %s: mean %.2f mm, p95 %.2f mm, max %.2f mm, availability %.1f %%, FRE %s mm"
                  % (r["seed"], m, quantile(r["e3"], 0.95), max(r["e3"]) if r["e3"] else float("nan"), av["percent"], fre or "?"))
    json.dump({"sensors": sensors[0], "seeds": n, "frames": len(pooled),
               "ar_error_3d_mm": {"mean": sum(pooled) / len(pooled) if pooled else None, "p95": quantile(pooled, 0.95),
                                  "max": max(pooled) if pooled else None},
               "per_seed_mean_mm": {"mean": mean_of_means, "sd": sd, "values": means},
               "availability_percent": 100.0 * shown / eligible if eligible else None, "eligible_frames": eligible},
              open(os.path.join(a.out, "seeds.json"), "w"), indent=2)


if __name__ == "__main__":
    main()
