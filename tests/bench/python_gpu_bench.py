#!/usr/bin/env python3
"""Zero-copy GPU arrays through contactgrid.Engine.detect against contactgrid_cuda_bench (issue #33).

    PYTHONPATH=<package> python3 tests/bench/python_gpu_bench.py [--min 20] [--max 24] [--runs 20]

The scene of contactgrid_cuda_bench (kernels/cuda/bench_cuda.cu, `spheres`): radii U[0.5, 1], centres
U[0, L)^3 with L = 2.65·N^(1/3) (NumPy's generator, not the bench's splitmix64: the same law). Inputs are
float64 device arrays exposing __cuda_array_interface__ (CuPy when importable, else contactgrid.DeviceArray);
per N and precision mode: the median wall time of Engine.detect(positions, radii) on one warm engine,
contacts left on the GPU (the Python call, the engine's bounds + plan + stages + its synchronisation).
contactgrid_cuda_bench's `total` column times Engine::detect_device_resident the same way, with the L2
cache flushed before every run (here: not flushed).
"""
import argparse
import statistics
import time

import numpy as np

import contactgrid


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--min", type=int, default=20)
    ap.add_argument("--max", type=int, default=24)
    ap.add_argument("--step", type=int, default=2)
    ap.add_argument("--runs", type=int, default=20)
    args = ap.parse_args()
    try:
        import cupy

        to_device, where = cupy.asarray, f"CuPy {cupy.__version__}"
    except ImportError:
        to_device, where = contactgrid.DeviceArray, "contactgrid.DeviceArray"
    print(f"contactgrid {contactgrid.__version__}, {contactgrid.cuda_device_count()} GPU(s), inputs: {where}")
    print(f"{'N':>10} {'mode':>6} {'contacts':>10} {'median ms':>10} {'min ms':>8}")
    for e in range(args.min, args.max + 1, args.step):
        n = 1 << e
        rng = np.random.default_rng(e)
        edge = 2.65 * n ** (1 / 3)
        positions = to_device(rng.uniform(0, edge, size=(n, 3)))
        radii = to_device(rng.uniform(0.5, 1.0, size=n))
        for mode in ("fp32", "mixed", "fp64"):
            engine = contactgrid.Engine(backend="cuda", precision=mode)
            contacts = engine.detect(positions, radii)  # warm: the workspace is allocated once
            times = []
            for _ in range(args.runs):
                t0 = time.perf_counter()
                contacts = engine.detect(positions, radii)
                times.append(time.perf_counter() - t0)
            assert contacts.on_device
            print(f"{n:>10} {mode:>6} {len(contacts):>10} {statistics.median(times) * 1e3:>10.3f} "
                  f"{min(times) * 1e3:>8.3f}", flush=True)


if __name__ == "__main__":
    main()
