"""Shared helpers of the Python tests (run by CTest with PYTHONPATH at the build tree's package and
CG_BINARY naming the contactgrid executable)."""
import os
import subprocess

import numpy as np
import pytest


@pytest.fixture
def cli():
    """Runs the contactgrid executable; returns the CompletedProcess (text output)."""
    binary = os.environ.get("CG_BINARY")
    if not binary or not os.path.exists(binary):
        pytest.skip("CG_BINARY does not name the contactgrid executable")

    def run(*args, check=True):
        p = subprocess.run([binary, *map(str, args)], capture_output=True, text=True)
        if check and p.returncode != 0:
            raise AssertionError(f"contactgrid {' '.join(map(str, args))}: exit {p.returncode}\n{p.stderr}")
        return p

    return run


def random_spheres(n, seed, contacts_per_body=2.0, r_low=0.5, r_high=1.0, dtype=np.float64):
    """n spheres, radii uniform in [r_low, r_high], centres uniform in a cube sized for about
    `contacts_per_body` contacts per sphere."""
    rng = np.random.default_rng(seed)
    r_mean = 0.5 * (r_low + r_high)
    edge = (n * 4.0 / 3.0 * np.pi * (2 * r_mean) ** 3 / (2 * contacts_per_body)) ** (1 / 3)
    positions = rng.uniform(0, edge, size=(n, 3)).astype(dtype)
    radii = rng.uniform(r_low, r_high, size=n).astype(dtype)
    return positions, radii


def sphere_pairs(positions, radii):
    """The exact oracle for spheres: every pair (a < b) with |a - b| <= ra + rb, by brute force in
    blocks; returns (id_a, id_b) sorted by (id_a, id_b)."""
    p = np.asarray(positions, dtype=np.float64)
    r = np.asarray(radii, dtype=np.float64)
    ids_a, ids_b = [], []
    for lo in range(0, len(p), 512):
        block = p[lo:lo + 512]
        d = np.sqrt(((block[:, None, :] - p[None, :, :]) ** 2).sum(-1))
        touch = d <= r[lo:lo + 512, None] + r[None, :]
        a, b = np.nonzero(touch)
        a = a + lo
        keep = a < b
        ids_a.append(a[keep])
        ids_b.append(b[keep])
    a = np.concatenate(ids_a)
    b = np.concatenate(ids_b)
    order = np.lexsort((b, a))
    return a[order], b[order]


def pytest_sessionfinish(session, exitstatus):
    """Exit 77 when every test skipped (CTest's SKIP_RETURN_CODE: shown as skipped, not passed)."""
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    if exitstatus == 0 and reporter is not None and reporter.stats.get("skipped") and not reporter.stats.get("passed"):
        session.exitstatus = 77


class DLPackOnly:
    """An array that exposes only the DLPack protocol (__dlpack__, __dlpack_device__) of the array it
    wraps: NumPy arrays for the CPU path, CuPy arrays or DeviceArray for CUDA. Keeps every capsule it
    handed out (`capsules`) and the keyword arguments of each call (`calls`), so tests can check that
    the consumer renamed them and which stream it asked for."""

    def __init__(self, array, device=None):
        self._array = array
        self._device = device  # a (type, id) to claim instead of the array's own
        self.capsules = []
        self.calls = []

    def __dlpack__(self, **kwargs):
        self.calls.append(kwargs)
        capsule = self._array.__dlpack__(**kwargs)
        self.capsules.append(capsule)
        return capsule

    def __dlpack_device__(self):
        return self._device if self._device is not None else self._array.__dlpack_device__()


def capsule_name(capsule):
    """The name of a PyCapsule ("dltensor" unused, "used_dltensor" once a consumer took it)."""
    import ctypes

    get = ctypes.pythonapi.PyCapsule_GetName
    get.restype, get.argtypes = ctypes.c_char_p, [ctypes.py_object]
    return get(capsule).decode()


def history_oracle(previous_pairs, pairs):
    """age and previous_row of each row of `pairs` (id_a, id_b arrays, sorted) given the pair lists of
    the earlier calls since the history began (`previous_pairs`, oldest first): age counts the
    consecutive earlier calls that had the pair, previous_row is its row in the last one (-1: new)."""
    a, b = pairs
    sets = [set(zip(pa.tolist(), pb.tolist())) for pa, pb in previous_pairs]
    rows = {}
    if previous_pairs:
        pa, pb = previous_pairs[-1]
        rows = {pair: k for k, pair in enumerate(zip(pa.tolist(), pb.tolist()))}
    age = np.zeros(len(a), dtype=np.int64)
    previous_row = np.full(len(a), -1, dtype=np.int64)
    for k, pair in enumerate(zip(a.tolist(), b.tolist())):
        n = 0
        while n < len(sets) and pair in sets[len(sets) - 1 - n]:
            n += 1
        age[k] = n
        previous_row[k] = rows.get(pair, -1)
    return age, previous_row
