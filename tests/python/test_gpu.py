"""GPU arrays (CUDA backend): inputs exposing __cuda_array_interface__ are read in place, and the
contacts stay on the GPU, exposed the same way. Our own DeviceArray stands for CuPy/PyTorch/Numba (the
device's CuPy, when present, is used too). Every test skips visibly without a GPU."""
import numpy as np
import pytest

import contactgrid
from conftest import random_spheres, sphere_pairs

pytestmark = pytest.mark.skipif(not contactgrid.cuda_available(), reason="no usable CUDA device")


@pytest.mark.parametrize("precision", ["fp64", "fp32", "mixed", "auto"])
def test_device_arrays_in_device_contacts_out(precision):
    p, r = random_spheres(50_000, 21)
    cpu = contactgrid.detect(p, r, backend="cpu", precision=precision)
    engine = contactgrid.Engine(backend="cuda", precision=precision, fields="full")
    dp, dr = contactgrid.DeviceArray(p), contactgrid.DeviceArray(r)
    assert dp.__cuda_array_interface__["typestr"] == "<f8" and dp.shape == (50_000, 3)
    got = engine.detect(dp, dr)
    assert got.on_device and got.backend == "cuda" and got.precision == cpu.precision and len(got) == len(cpu)
    interface = got.id_a.__cuda_array_interface__
    assert interface["version"] == 3 and interface["typestr"] == "<i8" and interface["shape"] == (len(cpu),)
    assert got.normal_on_b.__cuda_array_interface__["shape"] == (len(cpu), 3)
    for name in cpu.keys():  # the CUDA backend is bit for bit the CPU's
        np.testing.assert_array_equal(got[name].copy_to_host(), cpu[name], err_msg=name)
    host = got.to_host()
    assert not host.on_device
    np.testing.assert_array_equal(host.local_point_b, got.local_point_b.copy_to_host())


def test_device_contacts_are_invalid_after_the_engines_next_call():
    p, r = random_spheres(5000, 22)
    engine = contactgrid.Engine(backend="cuda", precision="fp64")
    first = engine.detect(contactgrid.DeviceArray(p), contactgrid.DeviceArray(r))
    kept = first.to_host()
    engine.detect(contactgrid.DeviceArray(p[:100]), contactgrid.DeviceArray(r[:100]))
    with pytest.raises(ValueError, match="overwritten"):
        first.id_a
    a, b = sphere_pairs(p, r)
    np.testing.assert_array_equal(kept.id_a, a)


def test_device_input_errors():
    p, r = random_spheres(100, 23)
    with pytest.raises(ValueError, match="float64"):
        contactgrid.detect(contactgrid.DeviceArray(p.astype(np.float32)), contactgrid.DeviceArray(r))
    with pytest.raises(ValueError, match="pass all on one side"):
        contactgrid.detect(contactgrid.DeviceArray(p), r)
    with pytest.raises(ValueError, match="CUDA backend"):
        contactgrid.detect(contactgrid.DeviceArray(p), contactgrid.DeviceArray(r), backend="cpu")
    bad = r.copy()
    bad[42] = np.nan
    with pytest.raises(contactgrid.InputError, match="42"):
        contactgrid.detect(contactgrid.DeviceArray(p), contactgrid.DeviceArray(bad), precision="fp64")


def test_cupy_arrays_when_cupy_is_there():
    cupy = pytest.importorskip("cupy")
    p, r = random_spheres(20_000, 24)
    got = contactgrid.detect(cupy.asarray(p), cupy.asarray(r), precision="fp64")
    id_a = cupy.asarray(got.id_a)  # zero copy: CuPy wraps the engine's memory
    assert id_a.data.ptr == got.id_a.pointer
    cpu = contactgrid.detect(p, r, backend="cpu", precision="fp64")
    np.testing.assert_array_equal(cupy.asnumpy(id_a), cpu.id_a)
    np.testing.assert_array_equal(cupy.asnumpy(cupy.asarray(got.distance)), cpu.distance)
