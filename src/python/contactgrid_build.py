"""The PEP 517 backend of src/python/pyproject.toml: a wheel of the package contactgrid, built by the
project's CMake. No setuptools: the wheel is a zip of what `cmake --install --component python` puts
under a staging prefix, with its METADATA, WHEEL and RECORD.

Config settings (pip --config-settings KEY=VALUE) or environment:
  build-dir / CONTACTGRID_BUILD_DIR   an existing or new CMake build folder (default: a temporary one)
  cmake-args / CONTACTGRID_CMAKE_ARGS extra configure arguments, space-separated
A build folder that is already configured is built as it is (its options are left alone).
"""
import base64
import hashlib
import os
import re
import shlex
import subprocess
import sys
import sysconfig
import tempfile
import zipfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))


def _version():
    with open(os.path.join(ROOT, "CMakeLists.txt")) as f:
        return re.search(r"project\(contactgrid VERSION ([0-9.]+)", f.read()).group(1)


def _setting(config_settings, key, env):
    value = (config_settings or {}).get(key) or os.environ.get(env)
    return value or None


def _tag():
    interpreter = f"cp{sys.version_info.major}{sys.version_info.minor}"
    platform = sysconfig.get_platform().replace("-", "_").replace(".", "_")
    return f"{interpreter}-{interpreter}{sys.abiflags}-{platform}"


def _metadata():
    return (f"Metadata-Version: 2.1\nName: contactgrid\nVersion: {_version()}\n"
            "Summary: Contact detection for spheres and ellipsoids on CPUs and GPUs\n"
            "Requires-Python: >=3.9\nRequires-Dist: numpy\n")


def _stage(build_dir, extra_args, stage):
    """Configures (when new), builds the module and installs the python component under `stage`;
    returns the staged package folder."""
    if not os.path.exists(os.path.join(build_dir, "CMakeCache.txt")):
        subprocess.run(["cmake", "-S", ROOT, "-B", build_dir, "-DCMAKE_BUILD_TYPE=Release",
                        f"-DPython3_EXECUTABLE={sys.executable}", "-DCONTACTGRID_ENABLE_TESTS=OFF",
                        "-DCONTACTGRID_ENABLE_BULLET=OFF", *extra_args], check=True)
    subprocess.run(["cmake", "--build", build_dir, "--target", "contactgrid_python", "contactgrid_python_files",
                    "-j", str(os.cpu_count() or 1)], check=True)
    subprocess.run(["cmake", "--install", build_dir, "--component", "python", "--prefix", stage], check=True)
    for folder, _, files in os.walk(stage):
        if os.path.basename(folder) == "contactgrid" and "__init__.py" in files:
            return folder
    raise RuntimeError(f"cmake --install put no contactgrid/__init__.py under {stage}")


def _record_line(name, data):
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{name},sha256={digest},{len(data)}"


def get_requires_for_build_wheel(config_settings=None):
    return []


def prepare_metadata_for_build_wheel(metadata_directory, config_settings=None):
    info = f"contactgrid-{_version()}.dist-info"
    os.makedirs(os.path.join(metadata_directory, info), exist_ok=True)
    with open(os.path.join(metadata_directory, info, "METADATA"), "w") as f:
        f.write(_metadata())
    return info


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    extra = shlex.split(_setting(config_settings, "cmake-args", "CONTACTGRID_CMAKE_ARGS") or "")
    with tempfile.TemporaryDirectory() as tmp:
        build_dir = _setting(config_settings, "build-dir", "CONTACTGRID_BUILD_DIR") or os.path.join(tmp, "build")
        package = _stage(os.path.abspath(build_dir), extra, os.path.join(tmp, "stage"))
        version = _version()
        info = f"contactgrid-{version}.dist-info"
        name = f"contactgrid-{version}-{_tag()}.whl"
        entries = []
        for file in sorted(os.listdir(package)):
            with open(os.path.join(package, file), "rb") as f:
                entries.append((f"contactgrid/{file}", f.read()))
        entries.append((f"{info}/METADATA", _metadata().encode()))
        entries.append((f"{info}/WHEEL", f"Wheel-Version: 1.0\nGenerator: contactgrid_build\nRoot-Is-Purelib: "
                                          f"false\nTag: {_tag()}\n".encode()))
        record = [_record_line(n, d) for n, d in entries] + [f"{info}/RECORD,,"]
        entries.append((f"{info}/RECORD", ("\n".join(record) + "\n").encode()))
        with zipfile.ZipFile(os.path.join(wheel_directory, name), "w", zipfile.ZIP_DEFLATED) as wheel:
            for n, d in entries:
                z = zipfile.ZipInfo(n, date_time=(2020, 1, 1, 0, 0, 0))
                z.external_attr = 0o755 << 16 if n.endswith(".so") else 0o644 << 16
                z.compress_type = zipfile.ZIP_DEFLATED
                wheel.writestr(z, d)
    return name
