"""GPU arrays (CUDA backend): inputs exposing __cuda_array_interface__ or DLPack are read in place, and
the contacts stay on the GPU, exposed both ways. Our own DeviceArray stands for CuPy/PyTorch/Numba (the
device's CuPy, when present, is used too). Contact identity (history=True) on device contacts and on
resident steps. Every test skips visibly without a GPU."""
import sys

import numpy as np
import pytest

import contactgrid
from conftest import DLPackOnly, capsule_name, random_spheres, sphere_pairs
from test_history import check_history, moving_bodies

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


def assert_same_contacts(a, b):
    assert a.keys() == b.keys() and len(a) > 0
    for name in a.keys():
        got = a[name].copy_to_host() if a.on_device else a[name]
        np.testing.assert_array_equal(got, b[name], err_msg=name)


def test_history_on_device_contacts():
    frames, r = moving_bodies(5000, 81)
    engine = contactgrid.Engine(backend="cuda", precision="fp64", history=True)
    cpu = contactgrid.Engine(backend="cpu", precision="fp64", history=True)
    hosts = []
    for p in frames:
        got = engine.detect(contactgrid.DeviceArray(p), contactgrid.DeviceArray(r))
        assert got.on_device and got.history and got.keys()[-2:] == ["age", "previous_row"]
        interface = got.age.__cuda_array_interface__
        assert interface["typestr"] == "<i8" and interface["shape"] == (len(got),)
        assert_same_contacts(got, cpu.detect(p, r))  # bit for bit the CPU engine's, history included
        hosts.append(got.to_host())
        np.testing.assert_array_equal(hosts[-1].previous_row, got.previous_row.copy_to_host())
    check_history(hosts, frames, r)
    engine.reset_history()
    fresh = engine.detect(contactgrid.DeviceArray(frames[0]), contactgrid.DeviceArray(r))
    assert (fresh.age.copy_to_host() == 0).all() and (fresh.previous_row.copy_to_host() == -1).all()
    plain = contactgrid.Engine(backend="cuda").detect(contactgrid.DeviceArray(frames[0]), contactgrid.DeviceArray(r))
    with pytest.raises(KeyError, match="history=True"):
        plain["age"]


def test_history_on_cuda_resident_steps():
    frames, r = moving_bodies(5000, 82)
    engine = contactgrid.Engine(backend="cuda", precision="fp64", history=True, skin=0.3)
    engine.set_resident(contactgrid.DeviceArray(frames[0]), contactgrid.DeviceArray(r))  # GPU arrays: via host
    results = [engine.detect_resident()]
    for p in frames[1:]:
        engine.write_resident(0, p, r)
        results.append(engine.detect_resident())
    check_history(results, frames, r)
    cpu = contactgrid.Engine(backend="cpu", precision="fp64", history=True, skin=0.3)
    cpu.set_resident(frames[0], r)
    for k, p in enumerate(frames):
        cpu.write_resident(0, p, r)
        assert_same_contacts(results[k], cpu.detect_resident())


def test_device_array_dlpack_round_trip():
    p, r = random_spheres(20_000, 83)
    want = contactgrid.detect(p, r, backend="cpu", precision="fp64", fields="full")
    dp, dr = contactgrid.DeviceArray(p), contactgrid.DeviceArray(r)
    assert dp.__dlpack_device__()[0] == 2  # kDLCUDA
    wp, wr = DLPackOnly(dp), DLPackOnly(dr)
    before = sys.getrefcount(dp), sys.getrefcount(dr)
    got = contactgrid.Engine(backend="cuda", precision="fp64", fields="full").detect(wp, wr)
    assert got.on_device
    assert_same_contacts(got, want)
    assert wp.calls == [{"stream": 1}] and capsule_name(wp.capsules[0]) == "used_dltensor"
    assert (sys.getrefcount(dp), sys.getrefcount(dr)) == before  # our deleter ran: the capsules let go
    cap = dp.__dlpack__()  # an unconsumed capsule releases its tensor when it goes
    assert capsule_name(cap) == "dltensor" and sys.getrefcount(dp) == before[0] + 1
    del cap
    assert sys.getrefcount(dp) == before[0]
    with pytest.raises(BufferError):
        dp.__dlpack__(copy=True)
    with pytest.raises(BufferError):
        dp.__dlpack__(dl_device=(1, 0))
    # A device contacts field, exported and read in place as another engine's input
    points = got.position_on_a
    k = len(points)
    again = contactgrid.Engine(backend="cuda", precision="fp64").detect(
        DLPackOnly(points), DLPackOnly(contactgrid.DeviceArray(np.full(k, 0.05))))
    assert_same_contacts(again, contactgrid.detect(points.copy_to_host(), np.full(k, 0.05), backend="cpu",
                                                   precision="fp64"))


def test_device_contacts_dlpack_is_invalid_after_the_engines_next_call():
    p, r = random_spheres(5000, 84)
    engine = contactgrid.Engine(backend="cuda", precision="fp64")
    field = engine.detect(contactgrid.DeviceArray(p), contactgrid.DeviceArray(r)).distance
    field.__dlpack__()
    engine.detect(contactgrid.DeviceArray(p[:100]), contactgrid.DeviceArray(r[:100]))
    with pytest.raises(ValueError, match="overwritten"):
        field.__dlpack__()


def test_cupy_through_dlpack_when_cupy_is_there():
    cupy = pytest.importorskip("cupy")
    p, r = random_spheres(20_000, 85)
    want = contactgrid.detect(p, r, backend="cpu", precision="fp64", fields="full")
    cp, cr = cupy.asarray(p), cupy.asarray(r)
    got = contactgrid.Engine(backend="cuda", precision="fp64", fields="full").detect(DLPackOnly(cp), DLPackOnly(cr))
    assert_same_contacts(got, want)
    distance = cupy.from_dlpack(got.distance)  # zero copy: CuPy views the engine's memory
    assert distance.data.ptr == got.distance.pointer
    np.testing.assert_array_equal(cupy.asnumpy(distance), want.distance)
    normals = cupy.from_dlpack(got.normal_on_b)
    assert normals.shape == (len(want), 3) and normals.data.ptr == got.normal_on_b.pointer
    np.testing.assert_array_equal(cupy.asnumpy(normals), want.normal_on_b)
    np.testing.assert_array_equal(cupy.asnumpy(cupy.from_dlpack(got.id_b)), want.id_b)
    engine = contactgrid.Engine(backend="cuda", precision="fp64", history=True)
    engine.set_resident(DLPackOnly(cp), DLPackOnly(cr))
    resident = engine.detect_resident()
    np.testing.assert_array_equal(resident.id_a, want.id_a)
    np.testing.assert_array_equal(resident.age, np.zeros(len(want), dtype=np.int64))
