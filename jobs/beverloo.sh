#!/usr/bin/env bash
# Hopper discharge against Beverloo's law (issue #32): 18 000 spheres (d = 2 mm, radii ±10 %) settle
# for 0.15 s on the closed plate of a cylinder 25 d wide (a bed about 60 mm high, at least twice the
# largest orifice to the end); from that frame three orifices (6, 7.5 and 9 grain diameters: above
# the clogging range of frictional spheres, below 1/2.5 of the cylinder) each drain for 0.25 s
# (12 500 steps of 20 µs); the mass flow rate from the frames, the exponent fitted with k = 1.4
# (jobs/beverloo.py; expected 2.5 ± 0.2). 45 000 steps of 18 000 bodies: sized for about a minute on
# one H100.
#   BIN=dir-with-contactgrid OUT=results-dir [BACKEND=cuda] [PYTHON=python with numpy, h5py] jobs/beverloo.sh [extra beverloo.py run options]
# Exit status non-zero when the exponent is outside 2.5 ± 0.2 or a bed fell below twice its orifice.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-build/src}; OUT=${OUT:-/tmp/beverloo}; BACKEND=${BACKEND:-cuda}
mkdir -p "$OUT"
exec "${PYTHON:-/usr/bin/python3}" jobs/beverloo.py run --contactgrid "$BIN/contactgrid" --out "$OUT" --backend "$BACKEND" "$@"
