"""Two simulate run directories hold the same bytes: every dataset of every .h5 file (frames only
with a third argument "frames"), and the log's steps, energies and contact counts (not its times).
Usage: same_run.py DIR1 DIR2 [all|frames]"""
import glob
import os
import sys

import h5py
import numpy as np

a, b = sys.argv[1:3]
what = sys.argv[3] if len(sys.argv) > 3 else "all"


def datasets(path):
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: out.__setitem__(n, o[()].tobytes()) if isinstance(o, h5py.Dataset) else None)
    return out


pattern = "frame_*.h5" if what == "frames" else "*.h5"
files = sorted(os.path.basename(p) for p in glob.glob(os.path.join(a, pattern)))
assert files, f"no files in {a}"
assert files == sorted(os.path.basename(p) for p in glob.glob(os.path.join(b, pattern))), "file lists differ"
for name in files:
    da, db = datasets(os.path.join(a, name)), datasets(os.path.join(b, name))
    assert da.keys() == db.keys(), f"{name}: datasets differ: {sorted(da)} vs {sorted(db)}"
    for k in da:
        assert da[k] == db[k], f"{name}/{k}: {a} and {b} differ"
if what == "all":
    la = np.genfromtxt(os.path.join(a, "log.csv"), delimiter=",", names=True, comments="#")
    lb = np.genfromtxt(os.path.join(b, "log.csv"), delimiter=",", names=True, comments="#")
    for col in ("step", "kinetic", "potential", "contacts"):
        assert la[col].tobytes() == lb[col].tobytes(), f"log.csv {col}: {a} and {b} differ"
print(f"same: {a} {b} ({len(files)} files)")
