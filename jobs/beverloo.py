#!/usr/bin/python3
"""Hopper discharge against Beverloo's law with contactgrid simulate (issue #32's hopper check).

A cylinder of spheres (radius R_cyl) first settles on a closed plate at z = 0 (walls
`hopper:0,0,R_cyl,0,0`); from its last frame (a scene file with velocities) each run opens a central
orifice of diameter D (walls `hopper:0,0,R_cyl,0,D/2`) and drains under gravity. The mass flow rate W is the slope of
the mass that has passed below the plate against time, from the run's frames, over the steady part
of the discharge; Beverloo's law is W = C rho_b sqrt(g) (D - k d)^n with n = 5/2. Three orifices give
three rates; the fit of log W against log(D - k d) (k fixed, 1.4 by default) gives n.

  beverloo.py run --contactgrid BIN/contactgrid --out DIR [--backend cuda] [--orifices 6 7.5 9]
  beverloo.py fit DIR1 DIR2 DIR3 --diameters D1 D2 D3 --d d   (the measurement alone, over run dirs)

The measurement (flow_rate, fit_exponent) is tested on synthetic frames by tests/python/test_beverloo.py.
"""
import argparse
import glob
import json
import os
import subprocess
import sys
import time

import h5py
import numpy as np


def write_hopper_scene(path, count, r_mean, spread, cyl_radius, seed):
    """Spheres on a jittered square lattice inside the cylinder, above the plate at z = 0."""
    rng = np.random.default_rng(seed)
    r_max = r_mean * (1 + spread)
    s = 2.05 * r_max
    reach = cyl_radius - r_max - 0.05 * s  # centres inside the cylinder by more than a radius
    m = int(np.floor(reach / s))
    grid = np.arange(-m, m + 1) * s
    gx, gy = np.meshgrid(grid, grid)
    inside = gx**2 + gy**2 <= reach**2
    layer = np.stack([gx[inside], gy[inside]], axis=1)
    layers = int(np.ceil(count / len(layer)))
    pos = []
    for k in range(layers):
        z = r_max + 0.05 * s + (k + 0.5) * s
        pos.append(np.column_stack([layer, np.full(len(layer), z)]))
    pos = np.concatenate(pos)[:count]
    pos[:, :2] += rng.uniform(-0.02 * s, 0.02 * s, size=(len(pos), 2))
    radius = r_mean * (1 + spread * rng.uniform(-1, 1, size=len(pos)))
    with h5py.File(path, "w") as f:
        f.create_dataset("spheres/position", data=pos.astype(np.float64))
        f.create_dataset("spheres/radius", data=radius.astype(np.float64))
        f.attrs["radius_low"] = float(radius.min())
        f.attrs["radius_high"] = float(radius.max())
        f.attrs["generator"] = "jobs/beverloo.py hopper"
    return pos[:, 2].max() + r_max


def frames_of(run_dir):
    """(time, z of every body, mass of every body / density) per frame, in step order."""
    out = []
    for path in sorted(glob.glob(os.path.join(run_dir, "frame_*.h5"))):
        with h5py.File(path, "r") as f:
            z = f["spheres/position"][:, 2]
            r = f["spheres/radius"][:]
            out.append((float(f.attrs["time"]), z, 4.0 / 3.0 * np.pi * r**3))
    return out


def flow_rate(frames, density, plate_z=0.0, skip=0.25):
    """The mass flow rate through the plate: the least-squares slope of the mass below it against
    time, over the frames after the first `skip` of those where anything has passed (the start-up of
    the flow). Returns (rate, times, passed masses)."""
    t = np.array([f[0] for f in frames])
    passed = np.array([density * f[2][f[1] < plate_z].sum() for f in frames])
    flowing = np.nonzero(passed > 0)[0]
    if len(flowing) < 4:
        raise ValueError("fewer than four frames with any mass below the plate: run longer")
    first = flowing[0] + int(np.ceil(skip * (len(t) - flowing[0])))
    window = slice(max(first, flowing[0]), len(t))
    if len(t[window]) < 3:
        raise ValueError("fewer than three frames in the steady window")
    slope, _ = np.polyfit(t[window], passed[window], 1)
    return float(slope), t, passed


def fit_exponent(diameters, rates, d, k=1.4):
    """Beverloo's exponent n and prefactor A of W = A (D - k d)^n by least squares in log-log."""
    x = np.log(np.asarray(diameters, dtype=float) - k * d)
    y = np.log(np.asarray(rates, dtype=float))
    n, log_a = np.polyfit(x, y, 1)
    return float(n), float(np.exp(log_a))


def bed_height(frames, plate_z=0.0):
    """The bed's height above the plate at the last frame (the 95th percentile of the centres above it)."""
    z = frames[-1][1]
    above = z[z > plate_z]
    return float(np.percentile(above, 95) - plate_z) if len(above) else 0.0


def run(args):
    os.makedirs(args.out, exist_ok=True)
    d = 2 * args.radius
    scene = os.path.join(args.out, "hopper.h5")
    top = write_hopper_scene(scene, args.count, args.radius, args.spread, args.cyl_radius, args.seed)
    def simulate(source, run_dir, steps, hole):
        subprocess.run(["rm", "-rf", run_dir], check=True)
        cmd = [args.contactgrid, "simulate", source, "-o", run_dir, "--steps", str(steps),
               "--dt", repr(args.dt), "--output-every", str(args.output_every), "--young", repr(args.young),
               "--density", repr(args.density), "--restitution", "0.5", "--friction", "0.5",
               "--rolling-friction", "0.05", "--walls", f"hopper:0,0,{args.cyl_radius!r},0,{hole!r}",
               "--backend", args.backend, "--precision", args.precision, "--no-plot", "-q"]
        t0 = time.time()
        subprocess.run(cmd, check=True)
        return time.time() - t0

    settle_dir = os.path.join(args.out, "settle")
    settle_seconds = simulate(scene, settle_dir, args.settle_steps, 0.0)
    settled = sorted(glob.glob(os.path.join(settle_dir, "frame_*.h5")))[-1]
    print(f"settled on the closed plate in {settle_seconds:.1f} s: bed {bed_height(frames_of(settle_dir)) * 1e3:.1f} mm",
          flush=True)
    rows = []
    for orifice in args.orifices:  # diameters in units of d
        D = orifice * d
        run_dir = os.path.join(args.out, f"D{orifice:g}d")
        seconds = simulate(settled, run_dir, args.steps, D / 2)
        frames = frames_of(run_dir)
        rate, _, passed = flow_rate(frames, args.density)
        bed = bed_height(frames)
        rows.append({"orifice_d": orifice, "D": D, "rate": rate, "passed": float(passed[-1]),
                     "bed_end": bed, "bed_over_D": bed / D, "seconds": seconds})
        print(f"D = {orifice:g} d: W = {rate:.5g} kg/s, bed at the end {bed / D:.2f} D, {seconds:.1f} s",
              flush=True)
    n, a = fit_exponent([r["D"] for r in rows], [r["rate"] for r in rows], d, args.k)
    result = {"exponent": n, "prefactor": a, "k": args.k, "d": d, "bodies": args.count, "lattice_top": top,
              "settle_seconds": settle_seconds, "runs": rows}
    with open(os.path.join(args.out, "beverloo.json"), "w") as f:
        json.dump(result, f, indent=1)
    print("| D/d | D (m) | W (kg/s) | bed at end / D | wall s |")
    print("|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['orifice_d']:g} | {r['D']:.4g} | {r['rate']:.4g} | {r['bed_over_D']:.2f} | {r['seconds']:.1f} |")
    print(f"Beverloo fit (k = {args.k}): exponent {n:.3f} (expected 2.5 +- 0.2), prefactor {a:.4g}")
    ok = abs(n - 2.5) <= 0.2 and all(r["bed_over_D"] >= 2 for r in rows)
    if not ok:
        print("FAILED: the exponent is outside 2.5 +- 0.2 or a bed fell below twice its orifice", file=sys.stderr)
    return 0 if ok else 1


def fit_dirs(args):
    rates = [flow_rate(frames_of(p), args.density)[0] for p in args.dirs]
    n, a = fit_exponent(args.diameters, rates, args.d, args.k)
    for p, D, w in zip(args.dirs, args.diameters, rates):
        print(f"{p}: D = {D:.4g}, W = {w:.5g}")
    print(f"exponent {n:.3f}, prefactor {a:.4g}")
    return 0


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="what", required=True)
    r = sub.add_parser("run")
    r.add_argument("--contactgrid", required=True)
    r.add_argument("--out", required=True)
    r.add_argument("--backend", default="cuda")
    r.add_argument("--precision", default="fp64")
    r.add_argument("--orifices", type=float, nargs="+", default=[6, 7.5, 9], help="diameters in units of d")
    r.add_argument("--count", type=int, default=18000)
    r.add_argument("--radius", type=float, default=1e-3, help="mean radius (d = 2 radius)")
    r.add_argument("--spread", type=float, default=0.1, help="radii uniform in radius (1 +- spread)")
    r.add_argument("--cyl-radius", type=float, default=0.025)
    r.add_argument("--young", type=float, default=1e6)
    r.add_argument("--density", type=float, default=2500)
    r.add_argument("--dt", type=float, default=2e-5)
    r.add_argument("--settle-steps", type=int, default=7500, help="on the closed plate, before the runs")
    r.add_argument("--steps", type=int, default=12500, help="of each discharge")
    r.add_argument("--output-every", type=int, default=500)
    r.add_argument("--k", type=float, default=1.4)
    r.add_argument("--seed", type=int, default=7)
    f = sub.add_parser("fit")
    f.add_argument("dirs", nargs="+")
    f.add_argument("--diameters", type=float, nargs="+", required=True)
    f.add_argument("--d", type=float, required=True)
    f.add_argument("--density", type=float, default=2500)
    f.add_argument("--k", type=float, default=1.4)
    args = p.parse_args()
    return run(args) if args.what == "run" else fit_dirs(args)


if __name__ == "__main__":
    sys.exit(main())
