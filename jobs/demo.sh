#!/usr/bin/env bash
# The README's main command: install, build, generate the default scene, detect, validate.
#   jobs/demo.sh [N]      (default N = 2^16 uniform spheres, radii in [0.5, 1], 0.4 contacts/sphere)
set -euo pipefail
cd "$(dirname "$0")/.."
N=${1:-65536}
jobs/install_deps.sh
jobs/build.sh
mkdir -p demo
CG=build/src/contactgrid
$CG generate demo/scene.h5 --count "$N" --seed 1
$CG detect demo/scene.h5 -o demo/contacts.h5
if $CG validate --help >/dev/null 2>&1; then
  $CG validate demo/scene.h5 demo/contacts.h5
fi
