"""contactgrid.detect on NumPy arrays: the exact oracle for spheres, the contract's conventions, the
options, the zero-copy views, the errors (with the command line's messages), the released GIL."""
import threading
import time

import numpy as np
import pytest

import contactgrid
from conftest import random_spheres, sphere_pairs


def test_two_spheres_as_the_readme_shows():
    contacts = contactgrid.detect(np.array([[0.0, 0, 0], [1.5, 0, 0]]), np.array([1.0, 1.0]), backend="cpu")
    assert len(contacts) == 1
    assert contacts.id_a.tolist() == [0] and contacts.id_b.tolist() == [1]
    assert contacts.distance.tolist() == [-0.5]
    assert contacts.normal_on_b.tolist() == [[-1.0, 0.0, 0.0]]  # from B towards A (docs/FORMAT.md §3)
    assert contacts.position_on_a.tolist() == [[1.0, 0.0, 0.0]]
    assert contacts.position_on_b.tolist() == [[0.5, 0.0, 0.0]]
    assert contacts.precision in ("fp64", "mixed") and contacts.precision_reason
    assert contacts.backend == "cpu" and contacts.bodies == 2
    assert "narrow" in contacts.times and all(t >= 0 for t in contacts.times.values())


@pytest.mark.parametrize("precision", ["fp64", "fp32", "mixed", "auto"])
@pytest.mark.parametrize("seed", [1, 2])
def test_random_spheres_match_the_exact_pairs(precision, seed):
    positions, radii = random_spheres(3000, seed)
    # fp32 may decide either way within its band (docs/PRECISION.md); these seeded scenes
    # have no pair that close to touching, so every mode must give the exact pairs.
    contacts = contactgrid.detect(positions, radii, backend="cpu", precision=precision, threads=2)
    a, b = sphere_pairs(positions, radii)
    np.testing.assert_array_equal(contacts.id_a, a)
    np.testing.assert_array_equal(contacts.id_b, b)
    real = np.float32 if precision == "fp32" else np.float64
    assert contacts.distance.dtype == real and contacts.normal_on_b.dtype == real
    # docs/FORMAT.md §3: n = (a − b)/d, position_on_b = b + rb·n, position_on_a = a − ra·n, distance = d − (ra + rb)
    pa, pb = positions[contacts.id_a], positions[contacts.id_b]
    d = np.linalg.norm(pa - pb, axis=1)
    tol = 1e-4 if precision == "fp32" else 1e-12
    np.testing.assert_allclose(contacts.distance, d - radii[contacts.id_a] - radii[contacts.id_b], atol=tol * 100)
    np.testing.assert_allclose(contacts.normal_on_b, (pa - pb) / d[:, None], atol=tol * 10)
    np.testing.assert_allclose(contacts.position_on_b, pb + radii[contacts.id_b, None] * contacts.normal_on_b,
                               atol=tol * 100)


def test_fields_are_views_of_the_result_without_a_copy():
    positions, radii = random_spheres(2000, 3)
    contacts = contactgrid.detect(positions, radii, backend="cpu")
    for name in contacts.keys():
        a, b = getattr(contacts, name), contacts[name]
        assert np.shares_memory(a, b), name  # both views of the engine's one result
        assert a.base is contacts, name  # the array keeps the result alive
        assert a.flags.c_contiguous
    del contacts
    assert a.sum() == a.sum()  # still valid once the Contacts object is gone


def test_other_layouts_and_dtypes_are_converted_once_with_the_same_result():
    positions, radii = random_spheres(1500, 4)
    reference = contactgrid.detect(positions, radii, backend="cpu", precision="fp64")
    fortran = np.asfortranarray(positions)
    strided = np.zeros((len(positions), 6))
    strided[:, ::2] = positions
    for p, r in [(fortran, radii), (strided[:, ::2], radii), (positions.tolist(), radii.tolist()),
                 (positions.astype(np.longdouble), radii[::-1][::-1])]:
        c = contactgrid.detect(p, r, backend="cpu", precision="fp64")
        np.testing.assert_array_equal(c.id_a, reference.id_a)
        np.testing.assert_array_equal(c.distance, reference.distance)
    # float32 input: the same bodies as float64 of the float32 values
    p32, r32 = positions.astype(np.float32), radii.astype(np.float32)
    c32 = contactgrid.detect(p32, r32, backend="cpu", precision="fp64")
    c64 = contactgrid.detect(p32.astype(np.float64), r32.astype(np.float64), backend="cpu", precision="fp64")
    np.testing.assert_array_equal(c32.id_b, c64.id_b)
    np.testing.assert_array_equal(c32.position_on_a, c64.position_on_a)
    # one radius for every body
    c1 = contactgrid.detect(positions, 0.75, backend="cpu")
    a, b = sphere_pairs(positions, np.full(len(positions), 0.75))
    np.testing.assert_array_equal(c1.id_a, a)


def test_fields_full_and_the_mapping_interface():
    positions, radii = random_spheres(500, 5)
    basic = contactgrid.detect(positions, radii, backend="cpu")
    full = contactgrid.detect(positions, radii, backend="cpu", fields="full")
    assert basic.keys() == ["id_a", "id_b", "position_on_a", "position_on_b", "normal_on_b", "distance"]
    assert full.keys() == basic.keys() + ["local_point_a", "local_point_b", "lateral_friction_dir1",
                                          "lateral_friction_dir2"]
    assert list(full) == full.keys() and "distance" in full and "age" not in full
    with pytest.raises(KeyError, match="fields='full'"):
        basic["local_point_a"]
    with pytest.raises(AttributeError):
        basic.local_point_a
    with pytest.raises(KeyError, match="not a contact field"):
        basic["nope"]
    np.testing.assert_allclose(full.local_point_a, full.position_on_a - positions[full.id_a], atol=1e-12)
    assert dict(zip(full.keys(), (full[k] for k in full)))["id_a"] is not None


def test_empty_and_apart():
    c = contactgrid.detect(np.zeros((0, 3)), np.zeros(0), backend="cpu")
    assert len(c) == 0 and c.id_a.shape == (0,) and c.normal_on_b.shape == (0, 3)
    c = contactgrid.detect(np.array([[0.0, 0, 0], [5, 0, 0]]), [1.0, 1.0], backend="cpu")
    assert len(c) == 0


def test_precision_auto_and_accuracy():
    positions, radii = random_spheres(1000, 6)
    loose = contactgrid.detect(positions, radii, backend="cpu", accuracy=1e-2)
    assert loose.precision == "fp32" and "fp32" in loose.precision_reason
    strict = contactgrid.detect(positions, radii, backend="cpu", accuracy=(1e-12, 1e-9))
    assert strict.precision in ("fp64", "mixed")
    with pytest.raises(ValueError, match="only with precision 'auto'"):
        contactgrid.detect(positions, radii, precision="fp32", accuracy=1e-3)
    with pytest.raises(contactgrid.InputError, match="no mode|meets|accuracy"):
        contactgrid.detect(positions + 1e9, radii, backend="cpu", accuracy=(1e-15, 1e-15))


def test_bad_options_and_shapes_raise_value_error():
    p, r = random_spheres(10, 7)
    for kwargs, text in [({"backend": "gpu"}, "backend: 'gpu'"), ({"precision": "fp16"}, "precision: 'fp16'"),
                         ({"fields": "all"}, "fields: 'all'"), ({"threads": -1}, "threads"),
                         ({"accuracy": -1.0}, "accuracy"), ({"accuracy": (1e-3, 1, 2)}, "accuracy")]:
        with pytest.raises(ValueError, match=text):
            contactgrid.detect(p, r, **kwargs)
    with pytest.raises(ValueError, match=r"positions: shape \(10, 2\), expected \(N, 3\)"):
        contactgrid.detect(p[:, :2], r)
    with pytest.raises(ValueError, match=r"radii: shape \(9,\)"):
        contactgrid.detect(p, r[:9])
    with pytest.raises(ValueError, match="radii: required"):
        contactgrid.detect(p)
    with pytest.raises(ValueError, match="not a number type"):
        contactgrid.detect(np.array([["a", "b", "c"]]), [1.0])


def test_bad_bodies_name_the_body_as_the_cli_does(tmp_path, cli):
    p, r = random_spheres(20, 8)
    bad = r.copy()
    bad[13] = -1.0
    with pytest.raises(contactgrid.InputError) as engine_error:
        contactgrid.detect(p, bad, backend="cpu", precision="fp64")
    assert isinstance(engine_error.value, ValueError)
    assert "13" in str(engine_error.value)
    # The same check, the same words, on the command line and through the module's scene reader.
    contactgrid.write_scene(tmp_path / "bad.h5", p, bad)
    run = cli("detect", tmp_path / "bad.h5", "-o", tmp_path / "c.h5", "--backend", "cpu", check=False)
    assert run.returncode == 3
    with pytest.raises(contactgrid.InputError) as read_error:
        contactgrid.read_scene(tmp_path / "bad.h5")
    assert run.stderr.strip() == f"contactgrid: error: {read_error.value}"
    nan = p.copy()
    nan[4, 1] = np.nan
    with pytest.raises(ValueError, match="4"):
        contactgrid.detect(nan, r, backend="cpu", precision="fp64")


def test_missing_file_is_the_cli_message(tmp_path, cli):
    run = cli("detect", tmp_path / "none.h5", "-o", tmp_path / "c.h5", check=False)
    with pytest.raises(ValueError) as e:
        contactgrid.read_scene(tmp_path / "none.h5")
    assert run.stderr.strip() == f"contactgrid: error: {e.value}"


def test_the_gil_is_released_while_the_engine_runs():
    positions, radii = random_spheres(1 << 18, 9)
    engine = contactgrid.Engine(backend="cpu", precision="fp64", threads=1)
    engine.detect(positions, radii)  # warm
    ticks = 0
    running = threading.Event()
    done = threading.Event()

    def count():
        nonlocal ticks
        running.set()
        while not done.is_set():
            ticks += 1

    t = threading.Thread(target=count)
    t.start()
    running.wait()
    start_ticks = ticks
    t0 = time.perf_counter()
    engine.detect(positions, radii)
    elapsed = time.perf_counter() - t0
    during = ticks - start_ticks
    done.set()
    t.join()
    # With the GIL held for the whole call the counting thread would get at most a switch interval
    # (5 ms) of it; released, it counts throughout.
    assert elapsed > 0.05, "scene too small to tell"
    assert during > 1000, f"{during} ticks in {elapsed:.3f} s"
