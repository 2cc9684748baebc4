"""Runs the Python code blocks of a Markdown page, in order, as one script (the page's example as
written): run_doc_example.py PAGE.md CONTACTGRID WORKDIR.

The blocks run in WORKDIR (emptied first) with CONTACTGRID in the environment. Exit 0 when they run
through, 1 when they fail (the traceback says where), 77 (CTest's SKIP_RETURN_CODE) when this
interpreter lacks numpy or h5py, saying so.
"""
import os
import re
import shutil
import sys


def main():
    page, binary, workdir = sys.argv[1:4]
    try:
        import h5py  # noqa: F401
        import numpy  # noqa: F401
    except ImportError as e:
        print(f"SKIP: {sys.executable} cannot import {e.name} (Debian: apt-get install python3-h5py "
              f"python3-numpy); {page} is not run")
        return 77
    with open(page, encoding="utf-8") as f:
        blocks = re.findall(r"^```python\n(.*?)^```", f.read(), flags=re.S | re.M)
    if not blocks:
        print(f"{page}: no ```python block")
        return 1
    shutil.rmtree(workdir, ignore_errors=True)
    os.makedirs(workdir)
    os.chdir(workdir)
    os.environ["CONTACTGRID"] = binary
    code = compile("\n".join(blocks), page, "exec")
    exec(code, {"__name__": "__main__"})
    print(f"{page}: {len(blocks)} block(s) ran")
    return 0


if __name__ == "__main__":
    sys.exit(main())
