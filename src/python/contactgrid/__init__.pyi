# Type stubs of the contactgrid package (the extension _contactgrid and __init__.py); docs/PYTHON.md.
from collections.abc import Iterator, Mapping
from os import PathLike
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

__version__: str

Backend = Literal["auto", "cpu", "cuda"]
PrecisionWord = Literal["auto", "fp32", "fp64", "mixed"]
FieldsWord = Literal["basic", "full"]
Accuracy = None | float | tuple[float, float]
ArrayIn = npt.ArrayLike | Any  # NumPy-convertible, or an object exposing __cuda_array_interface__ or DLPack
Path = str | PathLike[str]

class Error(RuntimeError): ...
class UsageError(ValueError): ...
class InputError(ValueError): ...
class IoError(OSError): ...
class ResourceError(MemoryError): ...
class CudaError(Error): ...
class MpiError(Error): ...

def cuda_available() -> bool: ...
def cuda_device_count() -> int: ...

class DeviceArray:
    def __init__(self, array: npt.ArrayLike) -> None: ...
    @property
    def __cuda_array_interface__(self) -> dict[str, Any]: ...
    @property
    def shape(self) -> tuple[int, ...]: ...
    @property
    def dtype(self) -> np.dtype[Any]: ...
    @property
    def pointer(self) -> int: ...
    def __dlpack__(
        self,
        *,
        stream: int | None = None,
        max_version: tuple[int, int] | None = None,
        dl_device: tuple[int, int] | None = None,
        copy: bool | None = None,
    ) -> Any: ...  # a PyCapsule named "dltensor"
    def __dlpack_device__(self) -> tuple[int, int]: ...
    def __len__(self) -> int: ...
    def copy_to_host(self) -> npt.NDArray[Any]: ...

FieldArray = npt.NDArray[np.int64] | npt.NDArray[np.float64] | npt.NDArray[np.float32] | DeviceArray

class Contacts:
    id_a: FieldArray
    id_b: FieldArray
    position_on_a: FieldArray
    position_on_b: FieldArray
    normal_on_b: FieldArray
    distance: FieldArray
    local_point_a: FieldArray
    local_point_b: FieldArray
    lateral_friction_dir1: FieldArray
    lateral_friction_dir2: FieldArray
    age: FieldArray
    previous_row: FieldArray
    def __len__(self) -> int: ...
    def __getitem__(self, name: str) -> FieldArray: ...
    def __contains__(self, name: object) -> bool: ...
    def __iter__(self) -> Iterator[str]: ...
    def keys(self) -> list[str]: ...
    @property
    def on_device(self) -> bool: ...
    @property
    def full(self) -> bool: ...
    @property
    def history(self) -> bool: ...
    @property
    def precision(self) -> Literal["fp32", "fp64", "mixed"]: ...
    @property
    def precision_reason(self) -> str: ...
    @property
    def backend(self) -> Literal["cpu", "cuda"]: ...
    @property
    def bodies(self) -> int: ...
    @property
    def times(self) -> dict[str, float]: ...
    @property
    def stats(self) -> dict[str, int | float]: ...
    @property
    def attributes(self) -> dict[str, int | float | str]: ...
    def to_host(self) -> Contacts: ...

class Engine:
    def __init__(
        self,
        *,
        backend: Backend = "auto",
        precision: PrecisionWord = "auto",
        accuracy: Accuracy = None,
        fields: FieldsWord = "basic",
        threads: int = 0,
        skin: float = 0.0,
        device: int = -1,
        history: bool = False,
    ) -> None: ...
    def detect(
        self,
        positions: ArrayIn,
        radii: ArrayIn | float | None = None,
        *,
        semi_axes: ArrayIn | None = None,
        orientations: ArrayIn | None = None,
    ) -> Contacts: ...
    def set_resident(
        self,
        positions: ArrayIn,
        radii: ArrayIn | float | None = None,
        *,
        semi_axes: npt.ArrayLike | None = None,
        orientations: npt.ArrayLike | None = None,
    ) -> None: ...
    def write_resident(self, first: int, positions: npt.ArrayLike, radii: npt.ArrayLike | float) -> None: ...
    def write_resident_shapes(
        self, first: int, semi_axes: npt.ArrayLike | None = None, orientations: npt.ArrayLike | None = None
    ) -> None: ...
    def read_resident(
        self, first: int = 0, count: int | None = None
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...
    def detect_resident(self) -> Contacts: ...
    def reset_history(self) -> None: ...
    @property
    def resident_size(self) -> int: ...
    @property
    def backend(self) -> Literal["cpu", "cuda"]: ...
    @property
    def precision(self) -> Literal["fp32", "fp64", "mixed"] | None: ...
    @property
    def stats(self) -> dict[str, int | float]: ...
    @property
    def times(self) -> dict[str, float]: ...

def detect(
    positions: ArrayIn,
    radii: ArrayIn | float | None = None,
    *,
    semi_axes: ArrayIn | None = None,
    orientations: ArrayIn | None = None,
    backend: Backend = "auto",
    precision: PrecisionWord = "auto",
    accuracy: Accuracy = None,
    fields: FieldsWord = "basic",
    threads: int = 0,
) -> Contacts: ...

class Scene(Mapping[str, npt.NDArray[np.float64]]):
    positions: npt.NDArray[np.float64]
    radii: npt.NDArray[np.float64]
    semi_axes: npt.NDArray[np.float64] | None
    orientations: npt.NDArray[np.float64] | None
    attributes: dict[str, int | float | str]
    radius_low: float | None
    radius_high: float | None
    spheres: int
    ellipsoids: int
    def __init__(
        self,
        positions: npt.NDArray[np.float64],
        radii: npt.NDArray[np.float64],
        semi_axes: npt.NDArray[np.float64] | None = None,
        orientations: npt.NDArray[np.float64] | None = None,
        attributes: dict[str, int | float | str] | None = None,
        radius_low: float | None = None,
        radius_high: float | None = None,
        spheres: int | None = None,
        ellipsoids: int | None = None,
    ) -> None: ...
    def __getitem__(self, key: str) -> npt.NDArray[np.float64]: ...
    def __iter__(self) -> Iterator[str]: ...
    def __len__(self) -> int: ...

def read_scene(path: Path) -> Scene: ...
def write_scene(
    path: Path,
    positions: npt.ArrayLike,
    radii: npt.ArrayLike | float | None = None,
    *,
    semi_axes: npt.ArrayLike | None = None,
    orientations: npt.ArrayLike | None = None,
    attributes: Mapping[str, int | float | str] | None = None,
    radius_low: float | None = None,
    radius_high: float | None = None,
) -> None: ...
def read_contacts(path: Path) -> Contacts: ...
def write_contacts(path: Path, contacts: Contacts) -> None: ...
