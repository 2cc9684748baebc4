"""`generate --xdmf` and `detect --xdmf`: the XDMF files ParaView opens, read back with a real XDMF
reader (meshio, Debian's python3-meshio) and checked against the HDF5 files they point into."""
import numpy as np
import pytest

import contactgrid

meshio = pytest.importorskip("meshio")


def rotation(q):
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def test_generate_xdmf_shows_spheres_and_ellipsoids(tmp_path, cli):
    cli("generate", tmp_path / "s.h5", "-n", 500, "--kind", "mixed", "--seed", 5, "--xdmf", "-q")
    scene = contactgrid.read_scene(tmp_path / "s.h5")
    n = scene.spheres
    spheres = meshio.read(tmp_path / "s.spheres.xmf")
    np.testing.assert_array_equal(spheres.points, scene.positions[:n])
    np.testing.assert_array_equal(spheres.point_data["radius"], scene.radii[:n])
    assert spheres.cells[0].type == "vertex" and len(spheres.cells[0].data) == n
    np.testing.assert_array_equal(spheres.cells[0].data.ravel(), np.arange(n))

    ellipsoids = meshio.read(tmp_path / "s.ellipsoids.xmf")
    np.testing.assert_array_equal(ellipsoids.points, scene.positions[n:])
    np.testing.assert_array_equal(ellipsoids.point_data["semi_axes"], scene.semi_axes[n:])
    np.testing.assert_array_equal(ellipsoids.point_data["orientation"], scene.orientations[n:])
    tensors = ellipsoids.point_data["shape"].reshape(-1, 3, 3)
    assert len(tensors) == scene.ellipsoids > 0
    for t, axes, q in zip(tensors, scene.semi_axes[n:], scene.orientations[n:]):
        r = rotation(q)  # the tensor's eigenvectors are the body's axes, its eigenvalues the semi-axes
        np.testing.assert_allclose(t @ r, r * axes, atol=1e-12)
        np.testing.assert_allclose(t, t.T, atol=1e-12)


def test_detect_xdmf_shows_contacts_with_normals_and_distances(tmp_path, cli):
    cli("generate", tmp_path / "s.h5", "-n", 2000, "--seed", 6, "-q")
    (tmp_path / "out").mkdir()
    cli("detect", tmp_path / "s.h5", "-o", tmp_path / "out" / "c.h5", "--xdmf", "--precision", "fp32", "-q")
    contacts = contactgrid.read_contacts(tmp_path / "out" / "c.h5")
    shown = meshio.read(tmp_path / "out" / "c.xmf")
    assert len(contacts) > 0 and len(shown.points) == len(contacts)
    assert shown.points.dtype == np.float32  # the file's own precision, pointed to, not copied
    np.testing.assert_array_equal(shown.points, contacts.position_on_b)
    np.testing.assert_array_equal(shown.point_data["normal_on_b"], contacts.normal_on_b)
    np.testing.assert_array_equal(shown.point_data["distance"], contacts.distance)
    np.testing.assert_array_equal(shown.point_data["id_a"], contacts.id_a)
    np.testing.assert_array_equal(shown.point_data["position_on_a"], contacts.position_on_a)
    # the bodies beside the contacts, pointing back into the scene file in its own folder
    bodies = meshio.read(tmp_path / "out" / "c.spheres.xmf")
    np.testing.assert_array_equal(bodies.points, contactgrid.read_scene(tmp_path / "s.h5").positions)
    assert "../s.h5:/spheres/position" in (tmp_path / "out" / "c.spheres.xmf").read_text()
    assert not (tmp_path / "out" / "c.ellipsoids.xmf").exists()


def test_no_xdmf_without_the_flag_and_none_for_a_failed_run(tmp_path, cli):
    cli("generate", tmp_path / "s.h5", "-n", 100, "-q")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.h5"]
    run = cli("detect", tmp_path / "missing.h5", "-o", tmp_path / "c.h5", "--xdmf", check=False)
    assert run.returncode == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.h5"]
