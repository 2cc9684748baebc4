"""The measurement of jobs/beverloo.py (the hopper discharge against Beverloo's law): the exponent fit,
the flow rate from a run's frames (synthetic frames with a known discharge), and the hopper scene it
writes, which contactgrid simulate accepts inside its walls."""
import os
import sys

import h5py
import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "jobs"))
import beverloo  # noqa: E402


@pytest.mark.parametrize("exponent", [2.5, 2.8, 2.0])
def test_fit_recovers_the_exponent_of_an_exact_law(exponent):
    d, k, a = 0.002, 1.4, 3.7
    diameters = np.array([5, 6.5, 8]) * d
    rates = a * (diameters - k * d) ** exponent
    n, fitted = beverloo.fit_exponent(diameters, rates, d, k)
    assert n == pytest.approx(exponent, abs=1e-9)
    assert fitted == pytest.approx(a, rel=1e-9)


def test_fit_with_noise_stays_within_the_tolerance():
    rng = np.random.default_rng(3)
    d = 0.002
    diameters = np.array([5, 6.5, 8]) * d
    rates = 2.0 * (diameters - 1.4 * d) ** 2.5 * (1 + 0.02 * rng.standard_normal(3))
    n, _ = beverloo.fit_exponent(diameters, rates, d)
    assert abs(n - 2.5) < 0.2


def write_frames(directory, rate, density, radius=1e-3, bodies=2000, frames=21, dt=0.01, start=0.05):
    """Frames of a discharge: nothing passes before `start`, then bodies pass the plate (z = 0) at a
    constant mass rate `rate`; the rest sit above it."""
    os.makedirs(directory, exist_ok=True)
    mass = density * 4.0 / 3.0 * np.pi * radius**3
    for f in range(frames):
        t = f * dt
        passed = int(np.floor(max(0.0, t - start) * rate / mass))
        z = np.full(bodies, 0.01)
        z[:passed] = -0.05
        pos = np.column_stack([np.zeros(bodies), np.zeros(bodies), z])
        with h5py.File(os.path.join(directory, f"frame_{f * 100:08d}.h5"), "w") as h:
            h.create_dataset("spheres/position", data=pos)
            h.create_dataset("spheres/radius", data=np.full(bodies, radius))
            h.attrs["time"] = t
            h.attrs["step"] = f * 100


def test_flow_rate_of_synthetic_frames(tmp_path):
    density, rate = 2500.0, 0.004
    write_frames(tmp_path / "run", rate, density)
    measured, t, passed = beverloo.flow_rate(beverloo.frames_of(str(tmp_path / "run")), density)
    assert measured == pytest.approx(rate, rel=0.03)
    assert passed[0] == 0 and passed[-1] > 0
    assert list(t) == sorted(t)


def test_flow_rate_refuses_a_run_without_discharge(tmp_path):
    write_frames(tmp_path / "run", 0.0, 2500.0)
    with pytest.raises(ValueError):
        beverloo.flow_rate(beverloo.frames_of(str(tmp_path / "run")), 2500.0)


def test_hopper_scene_sits_inside_its_walls(tmp_path, cli):
    scene = str(tmp_path / "hopper.h5")
    top = beverloo.write_hopper_scene(scene, 300, 1e-3, 0.1, 0.008, seed=1)
    with h5py.File(scene, "r") as f:
        p, r = f["spheres/position"][:], f["spheres/radius"][:]
    assert len(p) == 300 and top > 0
    assert (np.hypot(p[:, 0], p[:, 1]) + r < 0.008).all() and (p[:, 2] - r > 0).all()
    run = str(tmp_path / "run")
    cli("simulate", scene, "-o", run, "--steps", "20", "--dt", "2e-5", "--young", "1e6", "--walls",
        "hopper:0,0,0.008,0,0.004", "--backend", "cpu", "--no-plot", "-q")
    frames = beverloo.frames_of(run)
    assert len(frames) >= 2 and frames[-1][0] > 0
