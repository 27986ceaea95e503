#!/usr/bin/env python3
"""Writes the AR demo's scripted tool paths from a scene (docs/hil.md, "AR session"):

  make_demo_paths.py --scene SCENE.yaml --toward-camera X,Y,Z --out DIR

* DIR/landmarks.csv: four landmarks on the organ surface facing the camera, around the
  first tumour (name,x_mm,y_mm,z_mm in Model: the host's live registration targets);
* DIR/pointer_path.csv: the pointer comes in, dwells on each landmark (small jitter), leaves;
  it touches each landmark --touch-offset-mm LO,HI (default 2-4 mm, uniform) off the
  anatomical point, in a random direction (seeded by --seed) in the surface's tangent plane
  there (--touch-direction tangent, the default: the normal from the surface vertices within
  8 mm) or in 3-D (--touch-direction 3d): a surgeon does not find the exact anatomical point
  (issue 21). DIR/landmark_touches.csv lists the offsets (Model, mm);
* DIR/scalpel_path.csv: the scalpel waits outside, comes down to 5 mm off the surface
  beside the tumour, is drawn in over a quarter ring to the ring's depth (the blade tip
  --depth-mm past the tumour's far side) and traces the ring of radius (largest tumour
  radius + margin + clearance) at --speed mm/s, then lifts out;
* DIR/can_steps.yaml: arnav-can-sim steps: accept pressed in the middle of each dwell, the
  cut pedal held from before the plunge until after the lift (times shifted by --can-lead-s).
Rows: t_s,x_mm,y_mm,z_mm,qw,qx,qy,qz (tip in Model; the tool's +z points toward the camera,
along the blade from tip to heel). Geometry comes from the scene's tumour ellipsoid and the
organ surface mesh (legacy VTK polydata, ASCII or binary); nothing is tuned to one mesh.
"""
import argparse
import math
import os
import random
import struct
import sys


def fail(msg):
    print("make_demo_paths.py: " + msg, file=sys.stderr)
    sys.exit(2)


def read_scene(path):
    try:
        import yaml
    except ImportError:
        fail("python3-yaml is missing (Debian python3-yaml)")
    try:
        with open(path) as f:
            scene = yaml.safe_load(f)
    except yaml.YAMLError as e:
        m = getattr(e, "problem_mark", None)
        fail(f"{path}:{m.line + 1 if m else '?'}: not valid YAML ({getattr(e, 'problem', e)})")
    except OSError as e:
        fail(f"{path}: cannot read the scene ({e})")
    try:
        t = scene["structures"]["tumours"][0]["ellipsoid"]
        centre = [float(v) for v in t["center_mm"]]
        radii = [float(v) for v in t["radii_mm"]]
        surface = os.path.join(os.path.dirname(path), scene["organ"]["surface"])
    except (OSError, KeyError, IndexError, TypeError, ValueError) as e:
        fail(f"{path}: needs organ.surface and structures.tumours[0].ellipsoid {{center_mm, radii_mm}} ({e})")
    return centre, radii, surface


def read_vtk_points(path):
    try:
        data = open(path, "rb").read()
    except OSError as e:
        fail(f"{path}: cannot read the organ surface ({e})")
    lines = data.split(b"\n", 4)
    if len(lines) < 5 or not lines[0].startswith(b"# vtk DataFile"):
        fail(f"{path}: not a legacy VTK file")
    binary = lines[2].strip() == b"BINARY"
    i = data.find(b"POINTS ")
    if i < 0:
        fail(f"{path}: no POINTS section")
    eol = data.find(b"\n", i)
    _, n, kind = data[i:eol].split()
    n = int(n)
    body = data[eol + 1:]
    if binary:
        fmt, size = (">%df" % (3 * n), 4) if kind == b"float" else (">%dd" % (3 * n), 8)
        v = struct.unpack(fmt, body[:3 * n * size])
    else:
        v = [float(x) for x in body.split()[:3 * n]]
    return [(v[3 * k], v[3 * k + 1], v[3 * k + 2]) for k in range(n)]


def add(a, b, s=1.0):
    return [a[i] + s * b[i] for i in range(3)]


def dot(a, b):
    return sum(a[i] * b[i] for i in range(3))


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def unit(a):
    n = math.sqrt(dot(a, a))
    return [x / n for x in a]


def quat_z_to(d):
    """Unit quaternion (w, x, y, z) rotating +z onto unit vector d."""
    z = [0.0, 0.0, 1.0]
    c = dot(z, d)
    if c < -0.999999:
        return (0.0, 1.0, 0.0, 0.0)
    ax = cross(z, d)
    w = 1.0 + c
    n = math.sqrt(w * w + dot(ax, ax))
    return (w / n, ax[0] / n, ax[1] / n, ax[2] / n)


def surface_normal(pts, p, radius=8.0):
    """Unit normal of the surface points within `radius` of p (least-spread axis, power iteration)."""
    near = [q for q in pts if sum((q[i] - p[i]) ** 2 for i in range(3)) <= radius * radius]
    if len(near) < 3:
        return None
    c = [sum(q[i] for q in near) / len(near) for i in range(3)]
    C = [[sum((q[i] - c[i]) * (q[j] - c[j]) for q in near) for j in range(3)] for i in range(3)]
    tr = C[0][0] + C[1][1] + C[2][2]
    M = [[(tr if i == j else 0.0) - C[i][j] for j in range(3)] for i in range(3)]  # largest of M = smallest of C
    n = [0.3, 0.5, 0.8]
    for _ in range(200):
        n = unit([dot(M[i], n) for i in range(3)])
    return n


def touch_offset(rng, normal, lo, hi, direction):
    """An offset of length uniform in [lo, hi] mm, direction random in the tangent plane or in 3-D."""
    r = rng.uniform(lo, hi)
    if direction == "3d":
        d = unit([rng.gauss(0, 1) for _ in range(3)])
    else:
        e1 = unit(cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0]))
        e2 = cross(normal, e1)
        a = rng.uniform(0.0, 2.0 * math.pi)
        d = add([math.cos(a) * x for x in e1], e2, math.sin(a))
    return [r * x for x in d]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", required=True)
    ap.add_argument("--toward-camera", required=True, help="unit direction in Model from the organ toward the camera, X,Y,Z")
    ap.add_argument("--out", required=True)
    ap.add_argument("--margin-mm", type=float, default=5.0)
    ap.add_argument("--clearance-mm", type=float, default=3.0)
    ap.add_argument("--depth-mm", type=float, default=5.0, help="blade tip past the tumour's far side")
    ap.add_argument("--speed", type=float, default=20.0, help="ring speed, mm/s")
    ap.add_argument("--pointer-start-s", type=float, default=1.0)
    ap.add_argument("--dwell-s", type=float, default=1.8)
    ap.add_argument("--move-s", type=float, default=1.0)
    ap.add_argument("--gap-s", type=float, default=2.0, help="pause between the registration and the scalpel's plunge")
    ap.add_argument("--jitter-mm", type=float, default=0.1, help="sigma of the pointer's hand tremor during a dwell")
    ap.add_argument("--seed", type=int, default=1, help="seed of the touch offsets")
    ap.add_argument("--touch-offset-mm", default="2,4", help="LO,HI: how far off the anatomical point each landmark is touched")
    ap.add_argument("--touch-direction", choices=["tangent", "3d"], default="tangent")
    ap.add_argument("--can-lead-s", type=float, default=0.0, help="arnav-can-sim's clock minus the Polaris device clock")
    a = ap.parse_args()
    try:
        toward = [float(x) for x in a.toward_camera.split(",")]
        if len(toward) != 3:
            raise ValueError(a.toward_camera)
        toward = unit(toward)
    except (ValueError, ZeroDivisionError):
        fail("--toward-camera: expected three numbers X,Y,Z, not all zero, got '%s'" % a.toward_camera)
    try:
        touch_lo, touch_hi = [float(x) for x in a.touch_offset_mm.split(",")]
        if not 0 <= touch_lo <= touch_hi <= 50:
            raise ValueError(a.touch_offset_mm)
    except ValueError:
        fail("--touch-offset-mm: expected LO,HI with 0 <= LO <= HI <= 50 (mm), got '%s'" % a.touch_offset_mm)
    centre, radii, surface = read_scene(a.scene)
    pts = read_vtk_points(surface)
    # Lateral axes u, v perpendicular to the viewing direction.
    u = unit(cross(toward, [1.0, 0.0, 0.0] if abs(toward[0]) < 0.9 else [0.0, 1.0, 0.0]))
    v = cross(toward, u)

    def surface_toward_camera(p, radius):
        """The surface point nearest the camera within `radius` of the line through p along toward."""
        best = None
        for q in pts:
            d = [q[i] - p[i] for i in range(3)]
            h = dot(d, toward)
            lat = math.sqrt(max(0.0, dot(d, d) - h * h))
            if lat <= radius and (best is None or h > best[0]):
                best = (h, q)
        return best[1] if best else None

    os.makedirs(a.out, exist_ok=True)
    # Landmarks: surface vertices facing the camera around the tumour (not collinear).
    landmarks = []
    for k, (ang, r) in enumerate([(20, 50), (115, 40), (200, 55), (290, 45)]):
        c = add(add(centre, u, r * math.cos(math.radians(ang))), v, r * math.sin(math.radians(ang)))
        q = surface_toward_camera(c, 4.0)
        if q is None:
            fail(f"{surface}: no surface within 4 mm of the line through {c} toward the camera: landmark {k + 1}")
        landmarks.append(("lm%d" % (k + 1), list(q)))
    with open(os.path.join(a.out, "landmarks.csv"), "w") as f:
        f.write("name,x_mm,y_mm,z_mm\n")
        for n, p in landmarks:
            f.write("%s,%.3f,%.3f,%.3f\n" % (n, p[0], p[1], p[2]))
    # Where the pointer actually touches: off each anatomical point (seeded).
    touch_rng = random.Random(a.seed)
    touches = []
    for n, p in landmarks:
        normal = surface_normal(pts, p) or toward
        touches.append(add(p, touch_offset(touch_rng, normal, touch_lo, touch_hi, a.touch_direction)))
    with open(os.path.join(a.out, "landmark_touches.csv"), "w") as f:
        f.write("# make_demo_paths.py --seed %d --touch-offset-mm %s --touch-direction %s: where the pointer touches (Model)\n"
                % (a.seed, a.touch_offset_mm, a.touch_direction))
        f.write("name,x_mm,y_mm,z_mm,offset_mm\n")
        for (n, p), t in zip(landmarks, touches):
            f.write("%s,%.3f,%.3f,%.3f,%.3f\n" % (n, t[0], t[1], t[2], math.sqrt(sum((t[i] - p[i]) ** 2 for i in range(3)))))
    q_tool = quat_z_to(toward)
    rng = random.Random(12)

    def row(t, p):
        return "%.3f,%.3f,%.3f,%.3f,%.6f,%.6f,%.6f,%.6f\n" % ((t,) + tuple(p) + q_tool)

    rows, presses = ["t_s,x_mm,y_mm,z_mm,qw,qx,qy,qz\n"], []
    t = a.pointer_start_s
    rows.append(row(0.0, add(landmarks[0][1], toward, 80.0)))
    rows.append(row(t, add(landmarks[0][1], toward, 80.0)))
    for p in touches:
        t += a.move_s
        rows.append(row(t, p))
        t_arrive = t
        while t + 0.15 < t_arrive + a.dwell_s:
            t += 0.1
            rows.append(row(t, add(p, [rng.gauss(0, a.jitter_mm) for _ in range(3)])))
        t = t_arrive + a.dwell_s
        rows.append(row(t, p))
        presses.append(t_arrive + 0.5 * a.dwell_s)
    t += a.move_s
    rows.append(row(t, add(landmarks[-1][1], toward, 150.0)))
    with open(os.path.join(a.out, "pointer_path.csv"), "w") as f:
        f.writelines(rows)
    t_registered = t

    # Scalpel: ring around the tumour, blade tip past its far side.
    ring_r = max(radii) + a.margin_mm + a.clearance_mm
    far = math.sqrt(sum((radii[i] * toward[i]) ** 2 for i in range(3)))
    tip_centre = add(centre, toward, -(far + a.depth_mm))
    def on_ring(ang, lift_mm=0.0):
        return add(add(add(tip_centre, u, ring_r * math.cos(ang)), v, ring_r * math.sin(ang)), toward, lift_mm)

    # Entry: the blade is drawn in over the quarter ring before the start, from 5 mm off the
    # surface down to the ring's depth (an axial plunge sweeps no surface to cut along).
    entry_ang = -math.pi / 2
    top = surface_toward_camera(on_ring(entry_ang), 4.0)
    above_mm = (dot([top[i] - tip_centre[i] for i in range(3)], toward) + 5.0) if top else 60.0
    entry = on_ring(entry_ang, above_mm)
    outside = add(entry, toward, 60.0)
    rows = ["t_s,x_mm,y_mm,z_mm,qw,qx,qy,qz\n"]
    t = t_registered + a.gap_s
    rows.append(row(0.0, outside))
    rows.append(row(t, outside))
    t += 60.0 / a.speed
    rows.append(row(t, entry))
    t_plunge = t - 0.5
    n_entry = 16
    entry_len = math.hypot(ring_r * math.pi / 2, above_mm)
    for k in range(1, n_entry + 1):
        f = k / n_entry
        t += entry_len / a.speed / n_entry
        rows.append(row(t, on_ring(entry_ang * (1.0 - f), above_mm * (1.0 - f))))
    n = max(24, int(2 * math.pi * ring_r / 2.0))
    dt = 2 * math.pi * ring_r / a.speed / n
    for k in range(1, n + 1):
        t += dt
        rows.append(row(t, on_ring(2 * math.pi * k / n)))
    t_ring_done = t
    t += (above_mm + 60.0) / a.speed
    rows.append(row(t, add(on_ring(0.0), toward, above_mm + 60.0)))
    with open(os.path.join(a.out, "scalpel_path.csv"), "w") as f:
        f.writelines(rows)
    with open(os.path.join(a.out, "can_steps.yaml"), "w") as f:
        f.write("# arnav-can-sim steps for the AR demo, written by make_demo_paths.py: accept at each\n"
                "# landmark dwell, the cut pedal held through the ring.\nsteps:\n")
        for p in presses:
            f.write('  - {at_s: %.2f, do: "press pedal_accept"}\n' % (p + a.can_lead_s))
            f.write('  - {at_s: %.2f, do: "release pedal_accept"}\n' % (p + a.can_lead_s + 0.15))
        f.write('  - {at_s: %.2f, do: "press pedal_cut"}\n' % (t_plunge + a.can_lead_s))
        f.write('  - {at_s: %.2f, do: "release pedal_cut"}\n' % (t_ring_done + a.can_lead_s + 0.2))
    offs = [math.sqrt(sum((t_[i] - p[1][i]) ** 2 for i in range(3))) for t_, p in zip(touches, landmarks)]
    print("landmarks %d touched %.1f-%.1f mm off (%s, seed %d)" % (len(landmarks), min(offs), max(offs), a.touch_direction, a.seed))
    print("landmarks %d, ring radius %.1f mm, registration until %.1f s, ring %.1f-%.1f s, out %.1f s"
          % (len(landmarks), ring_r, t_registered, t_plunge, t_ring_done, t))


if __name__ == "__main__":
    main()
