#!/usr/bin/env python3
"""contactgrid.detect from Python against SciPy and against the same call from C++ (issue #33's benchmark).

    PYTHONPATH=build/src/python /usr/bin/python3 tests/bench/python_bench.py [--log2n 20] [--repetitions 5]

On one scene of 2^log2n uniform spheres (`contactgrid generate -n 2^log2n --seed log2n`, the CLI's
default density), each timed as the median wall time of repeated calls:
  contactgrid   contactgrid.detect(positions, radii, backend, precision, threads) on NumPy arrays
  scipy         cKDTree(positions).query_pairs(2·r_max, output_type="ndarray") + the NumPy filter to
                the touching pairs (|a − b| <= ra + rb): the pairs only, no contact data
  c++           detect_call_bench: the same call from C++ on the same file (tests/bench/detect_call_bench.cpp)
It checks that contactgrid and SciPy find the same pairs, and prints date, machine, commit and command.
"""
import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone

import numpy as np

import contactgrid

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def median_time(f, repetitions):
    f()  # warm
    times = []
    for _ in range(repetitions):
        t0 = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), times, out


def scipy_pairs(positions, radii):
    from scipy.spatial import cKDTree

    pairs = cKDTree(positions).query_pairs(2 * radii.max(), output_type="ndarray")
    a, b = pairs[:, 0], pairs[:, 1]
    d = np.linalg.norm(positions[a] - positions[b], axis=1)
    keep = d <= radii[a] + radii[b]
    return a[keep], b[keep]


def machine():
    model = ""
    try:
        with open("/proc/cpuinfo") as f:
            model = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return f"{platform.node()}: {model}, {os.cpu_count()} cores visible, load {os.getloadavg()[0]:.1f}"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--log2n", type=int, default=20)
    ap.add_argument("--repetitions", type=int, default=5)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--precision", default="auto")
    ap.add_argument("--backend", default="cpu")
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--binary", help="the contactgrid executable (default: BUILD/src/contactgrid)")
    ap.add_argument("--cxx", help="detect_call_bench (default: BUILD/tests/detect_call_bench)")
    ap.add_argument("--no-scipy", action="store_true")
    ap.add_argument("--scipy-repetitions", type=int, help="SciPy's timed calls (default: half of --repetitions)")
    args = ap.parse_args()

    binary = args.binary or os.path.join(args.build, "src", "contactgrid")
    cxx = args.cxx or os.path.join(args.build, "tests", "detect_call_bench")
    commit = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    dirty = subprocess.run(["git", "-C", ROOT, "status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True).stdout.strip()
    print(f"date     {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC")
    print(f"machine  {machine()}")
    print(f"commit   {commit}{' (+ local changes)' if dirty else ''}")
    print(f"command  {' '.join([os.path.basename(sys.executable)] + sys.argv)}")

    with tempfile.TemporaryDirectory() as tmp:
        scene_file = os.path.join(tmp, "scene.h5")
        n = 1 << args.log2n
        subprocess.run([binary, "generate", scene_file, "-n", str(n), "--seed", str(args.log2n), "-q"], check=True)
        scene = contactgrid.read_scene(scene_file)
        positions, radii = scene.positions, scene.radii
        print(f"scene    {n} uniform spheres (generate -n 2^{args.log2n} --seed {args.log2n}), "
              f"radii {radii.min():.3g} … {radii.max():.3g}")

        call = lambda: contactgrid.detect(positions, radii, backend=args.backend, precision=args.precision,  # noqa
                                          threads=args.threads)
        outside = []  # each call's wall time less its engine stages (contacts.times)
        stages = []  # each call's engine stages (the sum of contacts.times)

        def timed_call():
            t0 = time.perf_counter()
            c = call()
            stages.append(sum(c.times.values()))
            outside.append(time.perf_counter() - t0 - stages[-1])
            return c

        t_cg, all_cg, contacts = median_time(timed_call, args.repetitions)
        print(f"contactgrid.detect   {t_cg * 1e3:9.1f} ms  ({len(contacts)} contacts, precision "
              f"{contacts.precision}, backend {contacts.backend}; runs {' '.join(f'{t * 1e3:.1f}' for t in all_cg)})")
        print(f"  engine stages      {statistics.median(stages[1:]) * 1e3:9.1f} ms  (median of the sum of the "
              f"call's stage times, contacts.times)")
        print(f"  outside the engine {statistics.median(outside[1:]) * 1e3:9.1f} ms  (median of the call's wall time "
              f"less its stage times: bounds for precision auto, bindings, result object)")

        if os.path.exists(cxx):
            out = subprocess.run([cxx, scene_file, str(args.repetitions), str(args.threads), args.precision,
                                  args.backend], check=True, capture_output=True, text=True).stdout.split()
            t_cxx = float(out[out.index("median") + 1])
            assert int(out[out.index("contacts") + 1]) == len(contacts)
            print(f"same call from C++   {t_cxx * 1e3:9.1f} ms  (precision {out[1]}; runs "
                  f"{' '.join(f'{float(t) * 1e3:.1f}' for t in out[out.index('times') + 1:])})")
            print(f"  Python / C++       {t_cg / t_cxx:9.3f}")
        else:
            print(f"same call from C++   (build it: cmake --build {args.build} --target detect_call_bench)")

        if not args.no_scipy:
            sp_runs = args.scipy_repetitions or max(1, args.repetitions // 2)
            t_sp, all_sp, (a, b) = median_time(lambda: scipy_pairs(positions, radii), sp_runs)
            order = np.lexsort((b, a))
            same = np.array_equal(a[order], contacts.id_a) and np.array_equal(b[order], contacts.id_b)
            print(f"SciPy cKDTree        {t_sp * 1e3:9.1f} ms  ({len(a)} pairs, same pairs: {same}; runs "
                  f"{' '.join(f'{t * 1e3:.1f}' for t in all_sp)})")
            print(f"  SciPy / contactgrid {t_sp / t_cg:8.1f}x")
            if not same:
                return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
