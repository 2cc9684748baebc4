"""DLPack on the CPU: inputs that expose only __dlpack__ / __dlpack_device__ (NumPy's own producer,
wrapped so nothing else is visible) are taken through the protocol — capsule renamed "used_dltensor",
the producer's deleter called once the engine has read — and give the NumPy path's contacts; host
results hand themselves to np.from_dlpack without a copy. The GPU cases are in test_gpu.py."""
import sys

import numpy as np
import pytest

import contactgrid
from conftest import DLPackOnly, capsule_name, random_spheres

pytestmark = pytest.mark.skipif(not hasattr(np.ndarray, "__dlpack__"), reason="NumPy without DLPack (< 1.22)")


def assert_same_contacts(a, b):
    assert a.keys() == b.keys() and len(a) > 0
    for name in a.keys():
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_cpu_dlpack_inputs_give_the_numpy_paths_contacts():
    p, r = random_spheres(4000, 71)
    want = contactgrid.detect(p, r, backend="cpu", precision="fp64", fields="full")
    dp, dr = DLPackOnly(p), DLPackOnly(r)
    before = sys.getrefcount(p), sys.getrefcount(r)
    got = contactgrid.detect(dp, dr, backend="cpu", precision="fp64", fields="full")
    assert_same_contacts(got, want)
    # the protocol: one capsule each, consumed (renamed), no stream for a CPU producer, and the
    # producer's deleter called (NumPy's tensor holds a reference to its array until then)
    assert len(dp.capsules) == 1 and len(dr.capsules) == 1
    assert capsule_name(dp.capsules[0]) == "used_dltensor" and capsule_name(dr.capsules[0]) == "used_dltensor"
    assert dp.calls == [{}] and dr.calls == [{}]
    assert (sys.getrefcount(p), sys.getrefcount(r)) == before


def test_cpu_dlpack_other_dtypes_and_layouts_are_converted_once():
    p, r = random_spheres(3000, 72)
    p32, fortran = p.astype(np.float32), np.asfortranarray(p)
    want32 = contactgrid.detect(p32, r, backend="cpu", precision="fp64")
    assert_same_contacts(contactgrid.detect(DLPackOnly(p32), DLPackOnly(r), backend="cpu", precision="fp64"),
                         want32)
    want = contactgrid.detect(p, r, backend="cpu", precision="fp64")
    assert_same_contacts(contactgrid.detect(DLPackOnly(fortran), r, backend="cpu", precision="fp64"), want)
    wide = np.zeros((len(p), 6))
    wide[:, ::2] = p  # strided rows: DLPack strides in elements
    assert_same_contacts(contactgrid.detect(DLPackOnly(wide[:, ::2]), DLPackOnly(r[::1]), backend="cpu",
                                            precision="fp64"), want)
    radii_int = np.ones(len(p), dtype=np.int64)
    assert_same_contacts(contactgrid.detect(p, DLPackOnly(radii_int), backend="cpu", precision="fp64"),
                         contactgrid.detect(p, radii_int.astype(float), backend="cpu", precision="fp64"))


def test_cpu_dlpack_in_engine_and_resident_calls():
    p, r = random_spheres(3000, 73)
    want = contactgrid.detect(p, r, backend="cpu", precision="fp64")
    engine = contactgrid.Engine(backend="cpu", precision="fp64")
    assert_same_contacts(engine.detect(DLPackOnly(p), DLPackOnly(r)), want)
    engine.set_resident(DLPackOnly(p * 2), DLPackOnly(r))
    engine.write_resident(0, DLPackOnly(p), DLPackOnly(r))
    assert_same_contacts(engine.detect_resident(), want)


def test_dlpack_inputs_that_break_the_rules():
    p, r = random_spheres(100, 74)
    with pytest.raises(ValueError, match=r"positions: shape \(100, 2\), expected \(N, 3\)"):
        contactgrid.detect(DLPackOnly(p[:, :2].copy()), r, backend="cpu")
    with pytest.raises(ValueError, match="not a number type"):
        contactgrid.detect(p, DLPackOnly(np.ones(100, dtype=np.complex128)), backend="cpu")
    with pytest.raises(ValueError, match="neither the CPU"):
        contactgrid.detect(DLPackOnly(p, device=(4, 0)), r, backend="cpu")

    class NoCapsule(DLPackOnly):
        def __dlpack__(self, **kwargs):
            return "not a capsule"

    with pytest.raises(ValueError, match="dltensor"):
        contactgrid.detect(NoCapsule(p), r, backend="cpu")

    class UsedCapsule(DLPackOnly):  # hands out the same capsule again
        def __dlpack__(self, **kwargs):
            if not self.capsules:
                self.capsules.append(self._array.__dlpack__())
            return self.capsules[0]

    used = UsedCapsule(p)
    contactgrid.detect(used, r, backend="cpu")
    with pytest.raises(ValueError, match="unused"):
        contactgrid.detect(used, r, backend="cpu")

    class Liar(DLPackOnly):  # claims CUDA, hands out NumPy's host tensor (NumPy takes no stream)
        def __dlpack__(self, **kwargs):
            self.calls.append(kwargs)
            self.capsules.append(self._array.__dlpack__())
            return self.capsules[-1]

    # A producer claiming CUDA whose tensor is in host memory: refused, and its tensor released.
    liar = Liar(p, device=(2, 0))
    before = sys.getrefcount(p)
    with pytest.raises(ValueError, match="said CUDA"):
        contactgrid.detect(liar, Liar(r, device=(2, 0)))
    assert capsule_name(liar.capsules[0]) == "used_dltensor" and sys.getrefcount(p) == before
    assert liar.calls == [{"stream": 1}]  # a CUDA producer is handed the legacy default stream
    with pytest.raises(ValueError, match="pass all on one side"):
        contactgrid.detect(p, liar)


def test_host_contacts_go_to_numpy_through_dlpack_without_a_copy():
    p, r = random_spheres(1000, 75)
    contacts = contactgrid.Engine(backend="cpu", precision="fp64", history=True).detect(p, r)
    for name in ("distance", "normal_on_b", "id_a", "age"):
        view = np.from_dlpack(contacts[name])
        assert np.shares_memory(view, contacts[name])
        np.testing.assert_array_equal(view, contacts[name])
