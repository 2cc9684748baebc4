"""contactgrid.Engine (workspace, resident bodies, skin) and the files, checked against the command line:
the same scene detected through the module and through `contactgrid detect` gives the same bytes."""
import numpy as np
import pytest

import contactgrid
from conftest import random_spheres, sphere_pairs


def assert_same_contacts(a, b):
    assert a.keys() == b.keys()
    for name in a.keys():
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


@pytest.mark.parametrize("kind", ["uniform", "mixed", "ellipsoids"])
def test_module_and_cli_give_the_same_contacts(tmp_path, cli, kind):
    scene_file, cli_out, py_out = tmp_path / "s.h5", tmp_path / "cli.h5", tmp_path / "py.h5"
    cli("generate", scene_file, "-n", 3000, "--kind", kind, "--seed", 33, "-q")
    cli("detect", scene_file, "-o", cli_out, "--backend", "cpu", "--precision", "fp64", "--fields", "full", "-q")
    scene = contactgrid.read_scene(scene_file)
    assert (scene.semi_axes is not None) == (kind != "uniform")
    assert scene.spheres + scene.ellipsoids == 3000 and scene.attributes["seed"] == 33
    contacts = contactgrid.detect(**scene, backend="cpu", precision="fp64", fields="full")
    from_cli = contactgrid.read_contacts(cli_out)
    assert from_cli.precision == "fp64" and from_cli.attributes["bodies"] == 3000
    assert len(contacts) > 0
    assert_same_contacts(contacts, from_cli)
    contactgrid.write_contacts(py_out, contacts)
    assert "IDENTICAL" in cli("compare", cli_out, py_out).stdout


def test_scene_files_round_trip(tmp_path):
    scene = {"positions": np.array([[0.0, 0, 0], [1, 2, 3], [4, 5, 6]]), "radii": np.array([1.0, 0.5, 2.0]),
             "semi_axes": np.array([[1.0, 1, 1], [0.5, 0.5, 0.5], [2.0, 1, 0.5]]),
             "orientations": np.array([[1.0, 0, 0, 0], [1, 0, 0, 0], [0, 1, 0, 0]])}
    contactgrid.write_scene(tmp_path / "s.h5", **scene, attributes={"note": "hand made", "n": 3, "x": 0.5},
                            radius_low=0.5, radius_high=2.0)
    back = contactgrid.read_scene(tmp_path / "s.h5")
    assert back.spheres == 2 and back.ellipsoids == 1
    for k, v in scene.items():
        np.testing.assert_array_equal(back[k], v, err_msg=k)
    assert back.attributes["note"] == "hand made" and back.attributes["n"] == 3 and back.attributes["x"] == 0.5
    assert (back.radius_low, back.radius_high) == (0.5, 2.0)
    assert sorted(back) == ["orientations", "positions", "radii", "semi_axes"]
    with pytest.raises(ValueError, match="spheres first"):
        contactgrid.write_scene(tmp_path / "t.h5", scene["positions"][::-1], semi_axes=scene["semi_axes"][::-1])
    with pytest.raises(ValueError, match="largest semi-axis"):
        contactgrid.write_scene(tmp_path / "t.h5", scene["positions"], [1.0, 0.5, 1.5], semi_axes=scene["semi_axes"])
    with pytest.raises(OSError):
        contactgrid.write_scene(tmp_path / "no" / "dir.h5", scene["positions"], scene["radii"])


def test_sphere_only_scene_reads_without_shape_rows(tmp_path):
    p, r = random_spheres(100, 10)
    contactgrid.write_scene(tmp_path / "s.h5", p, r)
    s = contactgrid.read_scene(tmp_path / "s.h5")
    assert s.semi_axes is None and s.orientations is None and list(s) == ["positions", "radii"]
    np.testing.assert_array_equal(s.positions, p)
    assert s.positions.flags.c_contiguous and s.positions.base is not None  # owns the rows read


def test_engine_keeps_its_workspace_and_gives_fresh_results():
    engine = contactgrid.Engine(backend="cpu", precision="fp64")
    assert engine.precision == "fp64" and engine.backend == "cpu"
    first = None
    for seed in (11, 12, 11):
        p, r = random_spheres(2000, seed)
        c = engine.detect(p, r)
        a, b = sphere_pairs(p, r)
        np.testing.assert_array_equal(c.id_a, a)
        np.testing.assert_array_equal(c.id_b, b)
        if first is None:
            first = c
    np.testing.assert_array_equal(first.id_a, c.id_a)  # the first result is intact: host results are owned
    assert engine.stats["bodies"] == 2000 and engine.stats["contacts"] == len(c)


def test_engine_auto_chooses_once():
    engine = contactgrid.Engine(backend="cpu", accuracy=1e-2)
    assert engine.precision is None
    p, r = random_spheres(500, 13)
    assert engine.detect(p, r).precision == "fp32"
    assert engine.precision == "fp32"
    assert engine.detect(p * 3, r).precision == "fp32"  # kept, whatever the next bodies


def test_resident_bodies_with_a_skin_match_fresh_detection():
    p, r = random_spheres(4000, 14)
    rng = np.random.default_rng(14)
    engine = contactgrid.Engine(backend="cpu", precision="fp64", skin=0.2)
    engine.set_resident(p, r)
    assert engine.resident_size == 4000
    for step in range(6):
        p = p + rng.uniform(-0.01, 0.01, size=p.shape)
        engine.write_resident(0, p, r)
        got = engine.detect_resident()
        want = contactgrid.detect(p, r, backend="cpu", precision="fp64")
        assert_same_contacts(got, want)
    assert engine.stats["candidate_reuses"] > 0
    back_p, back_r = engine.read_resident(10, 5)
    np.testing.assert_array_equal(back_p, p[10:15])
    np.testing.assert_array_equal(back_r, r[10:15])
    with pytest.raises(ValueError, match="outside"):
        engine.write_resident(3999, p[:2], r[:2])


def test_resident_ellipsoids_turn_in_place(tmp_path, cli):
    cli("generate", tmp_path / "e.h5", "-n", 1500, "--kind", "ellipsoids", "--seed", 15, "-q")
    scene = contactgrid.read_scene(tmp_path / "e.h5")
    engine = contactgrid.Engine(backend="cpu", precision="fp64")
    engine.set_resident(**scene)
    turned = scene.orientations[:, [1, 0, 3, 2]] * np.array([-1, 1, 1, -1])  # q·(0, 1, 0, 0): a half turn
    engine.write_resident_shapes(0, orientations=turned)
    got = engine.detect_resident()
    want = contactgrid.detect(scene.positions, semi_axes=scene.semi_axes, orientations=turned,
                              backend="cpu", precision="fp64")
    assert_same_contacts(got, want)


def test_no_resident_bodies_is_a_usage_error():
    engine = contactgrid.Engine(backend="cpu")
    with pytest.raises(ValueError, match="set_resident"):
        engine.detect_resident()


def test_device_arrays_need_a_gpu_build_or_device():
    if contactgrid.cuda_available():
        pytest.skip("a GPU is present (tests/python/test_gpu.py covers it)")
    with pytest.raises(contactgrid.CudaError):
        contactgrid.Engine(backend="cuda", precision="fp64")
    with pytest.raises(contactgrid.CudaError):  # precision "auto": the engine is made by the first call
        contactgrid.detect(np.zeros((2, 3)), 1.0, backend="cuda")
