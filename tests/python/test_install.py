"""The module as installed: `cmake --install <build> --component python` puts the package into the
interpreter's site-packages below the prefix; a fresh interpreter imports it from there alone."""
import os
import subprocess
import sys

import pytest


def test_cmake_install_puts_an_importable_package_under_the_prefix(tmp_path):
    build, where = os.environ.get("CG_BUILD_DIR"), os.environ.get("CG_PYTHON_INSTALL_DIR")
    if not build or not where:
        pytest.skip("CG_BUILD_DIR / CG_PYTHON_INSTALL_DIR not set (CTest sets them)")
    prefix = tmp_path / "prefix"
    subprocess.run(["cmake", "--install", build, "--component", "python", "--prefix", str(prefix)], check=True,
                   capture_output=True)
    package = prefix / where / "contactgrid"
    names = sorted(os.listdir(package))
    assert "__init__.py" in names and "__init__.pyi" in names and "py.typed" in names
    assert any(n.startswith("_contactgrid.") and n.endswith(".so") for n in names), names
    code = ("import contactgrid, numpy as np; c = contactgrid.detect(np.array([[0., 0, 0], [1.5, 0, 0]]), 1.0, "
            "backend='cpu'); print(contactgrid.__file__, len(c), c.distance[0])")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONPATH"] = str(prefix / where)
    out = subprocess.run([sys.executable, "-c", code], env=env, check=True, capture_output=True, text=True,
                         cwd=tmp_path).stdout.split()
    assert out[0].startswith(str(package)) and out[1:] == ["1", "-0.5"]


def test_pip_install_builds_a_wheel_through_cmake(tmp_path):
    build = os.environ.get("CG_BUILD_DIR")
    if not build:
        pytest.skip("CG_BUILD_DIR not set (CTest sets it)")
    source = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "src",
                          "python")
    target = tmp_path / "site"
    # The build tree of this suite is reused (already configured: built as it is), so the test does not
    # rebuild the project; a fresh clone's `pip install --no-build-isolation src/python` configures its own.
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-build-isolation", "--no-deps", "--no-index",
                    "--target", str(target), "--config-settings", f"build-dir={build}", source],
                   check=True, capture_output=True)
    names = sorted(os.listdir(target))
    assert "contactgrid" in names and any(n.startswith("contactgrid-") and n.endswith(".dist-info") for n in names)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONPATH"] = str(target)
    out = subprocess.run([sys.executable, "-c", "import contactgrid; print(contactgrid.__file__, "
                          "contactgrid.__version__)"], env=env, check=True, capture_output=True, text=True,
                         cwd=tmp_path).stdout.split()
    import contactgrid

    assert out[0].startswith(str(target)) and out[1] == contactgrid.__version__


def test_type_stubs_name_what_the_module_has():
    """Every class member and keyword the stubs declare exists at runtime, and the reverse for the
    public methods of Engine, Contacts and DeviceArray (a stub that drifts from the module fails here)."""
    import ast
    import re

    import contactgrid

    tree = ast.parse(open(os.path.join(os.path.dirname(contactgrid.__file__), "__init__.pyi")).read())
    classes = {c.name: c for c in tree.body if isinstance(c, ast.ClassDef)}
    for name in ("Engine", "Contacts", "DeviceArray"):
        declared = {n.name for n in classes[name].body if isinstance(n, ast.FunctionDef)}
        runtime = {m for m in dir(getattr(contactgrid, name)) if not m.startswith("_")}
        runtime -= {"id_a", "id_b", "position_on_a", "position_on_b", "normal_on_b", "distance"}  # fields
        assert runtime <= declared, (name, runtime - declared)
        for member in declared - {"__init__"}:
            assert hasattr(getattr(contactgrid, name), member), (name, member)
    init = next(n for n in classes["Engine"].body if isinstance(n, ast.FunctionDef) and n.name == "__init__")
    stub_keywords = [a.arg for a in init.args.kwonlyargs]
    doc_keywords = re.findall(r"(\w+): \w+ = ", contactgrid.Engine.__init__.__doc__.splitlines()[0])
    assert stub_keywords == doc_keywords, (stub_keywords, doc_keywords)
