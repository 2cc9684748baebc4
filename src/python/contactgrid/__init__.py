"""contactgrid: every touching or overlapping pair of spheres and ellipsoids, with Bullet's contact data.

    import numpy as np, contactgrid
    contacts = contactgrid.detect(np.array([[0, 0, 0], [1.5, 0, 0]]), np.array([1.0, 1.0]))
    contacts.id_a, contacts.id_b, contacts.distance      # [0] [1] [-0.5]

detect() on NumPy arrays (or GPU arrays exposing __cuda_array_interface__ or DLPack), Engine for
loops that call it again and again (history=True: contact identity across calls), read_scene / write_scene / read_contacts / write_contacts for the HDF5
files of the command line. Errors carry the command line's messages: InputError and UsageError are
ValueErrors, ResourceError a MemoryError, IoError an OSError. docs/PYTHON.md is the reference.
"""

import os
from collections.abc import Mapping

from ._contactgrid import (
    Contacts,
    CudaError,
    DeviceArray,
    Engine,
    Error,
    InputError,
    IoError,
    MpiError,
    ResourceError,
    UsageError,
    __version__,
    cuda_available,
    cuda_device_count,
)
from ._contactgrid import _read_contacts, _read_scene, _write_contacts, _write_scene

__all__ = [
    "Contacts",
    "CudaError",
    "DeviceArray",
    "Engine",
    "Error",
    "InputError",
    "IoError",
    "MpiError",
    "ResourceError",
    "Scene",
    "UsageError",
    "__version__",
    "cuda_available",
    "cuda_device_count",
    "detect",
    "read_contacts",
    "read_scene",
    "write_contacts",
    "write_scene",
]

_BODY_FIELDS = ("positions", "radii", "semi_axes", "orientations")


def detect(
    positions,
    radii=None,
    *,
    semi_axes=None,
    orientations=None,
    backend="auto",
    precision="auto",
    accuracy=None,
    fields="basic",
    threads=0,
):
    """Every touching or overlapping pair of bodies, sorted by (id_a, id_b); body i has id i.

    positions     (N, 3) centres, world frame.
    radii         (N,) radii, or one number for every body. With semi_axes: None (each body's
                  largest semi-axis), or exactly those values.
    semi_axes     (N, 3) semi-axes along each body's local x, y, z (scenes with ellipsoids). A body
                  whose three semi-axes are equal is a sphere (the sphere's closed form).
    orientations  (N, 4) unit quaternions (w, x, y, z), body to world; None: the identity.
    backend       "auto" (CUDA when a GPU is usable), "cpu" or "cuda".
    precision     "auto" (the cheapest mode whose documented bounds meet `accuracy` for these
                  bodies), "fp32", "fp64" or "mixed"; contacts.precision says which ran.
    accuracy      precision "auto" only: None (what fp64 gives), a number (position error relative
                  to the smallest radius) or (position, normal angle in degrees).
    fields        "basic" or "full" (also local points and friction directions).
    threads       CPU backend threads (0: all cores).

    Arrays: float64 in C order are read in place. Any other dtype (float32, integers) or layout
    (Fortran order, slices with strides, lists) is converted to float64 C order once, a copy.
    Objects exposing DLPack (__dlpack__, __dlpack_device__) on the CPU are taken the same way.
    GPU arrays (CUDA backend): positions and radii exposing __cuda_array_interface__ (v2 or v3) or
    DLPack on a CUDA device (float64, C order) are read in place, and the contacts stay on the GPU:
    their fields are DeviceArray objects exposing __cuda_array_interface__ and DLPack (CuPy, PyTorch
    and Numba take them). Spheres only on that path.

    Returns Contacts: fields as NumPy arrays over the engine's result (no copy), float32 for
    precision "fp32". The GIL is released while the engine runs. Bad bodies raise InputError
    (a ValueError) naming the first bad body, bad options ValueError, memory ResourceError.
    For repeated calls keep an Engine: it keeps its workspace.
    """
    engine = Engine(backend=backend, precision=precision, accuracy=accuracy, fields=fields, threads=threads)
    return engine.detect(positions, radii, semi_axes=semi_axes, orientations=orientations)


class Scene(Mapping):
    """A scene file's bodies in id order (spheres, then ellipsoids), as detect() takes them.

    A mapping of the body arrays present (positions, radii and, with ellipsoids, semi_axes and
    orientations; spheres have semi-axes (r, r, r) and the identity orientation), so
    contactgrid.detect(**scene) detects it; attributes, radius_low, radius_high, spheres and
    ellipsoids are attributes.
    """

    def __init__(self, positions, radii, semi_axes=None, orientations=None, attributes=None,
                 radius_low=None, radius_high=None, spheres=None, ellipsoids=None):
        self.positions = positions
        self.radii = radii
        self.semi_axes = semi_axes
        self.orientations = orientations
        self.attributes = dict(attributes or {})
        self.radius_low = radius_low
        self.radius_high = radius_high
        self.spheres = len(radii) if spheres is None else spheres
        self.ellipsoids = 0 if ellipsoids is None else ellipsoids

    def __getitem__(self, key):
        if key not in _BODY_FIELDS or getattr(self, key) is None:
            raise KeyError(key)
        return getattr(self, key)

    def __iter__(self):
        return (k for k in _BODY_FIELDS if getattr(self, k) is not None)

    def __len__(self):
        return sum(1 for _ in self)

    def __repr__(self):
        return f"<contactgrid.Scene: {self.spheres} spheres, {self.ellipsoids} ellipsoids>"


def read_scene(path):
    """The bodies of a scene file (docs/FORMAT.md §1) as a Scene: float64 arrays holding the rows read
    (no further copy). InputError (a ValueError) names the file, dataset and first bad row."""
    return Scene(**_read_scene(os.fspath(path)))


def write_scene(path, positions, radii=None, *, semi_axes=None, orientations=None, attributes=None,
                radius_low=None, radius_high=None):
    """Writes a scene file (docs/FORMAT.md §1): bodies as detect() takes them, spheres (equal semi-axes)
    before ellipsoids, since a file numbers its spheres first. `attributes`: root attributes
    (int, float or str values); radius_low / radius_high: the radius bounds the file promises.
    Written to a temporary name and renamed when complete; IoError (an OSError) on failure.
    write_scene(path, **read_scene(other)) copies a scene's bodies."""
    _write_scene(os.fspath(path), positions, radii, semi_axes, orientations, dict(attributes or {}),
                 radius_low, radius_high)


def read_contacts(path):
    """The contacts of a contact file (docs/FORMAT.md §2) as Contacts of float64 arrays, whatever precision
    wrote them (contacts.precision says which); contacts.attributes holds the file's root
    attributes. InputError (a ValueError) names the file and dataset of bad data."""
    return _read_contacts(os.fspath(path))


def write_contacts(path, contacts):
    """Writes host contacts as `contactgrid detect -o` does (docs/FORMAT.md §2, the run's record as root
    attributes), to a temporary name renamed over `path` when complete. IoError (an OSError) when
    the file cannot be written. Device contacts: write contacts.to_host()."""
    _write_contacts(os.fspath(path), contacts)
