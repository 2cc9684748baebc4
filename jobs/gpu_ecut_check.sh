#!/usr/bin/env bash
# The ellipsoid skin cut by the centre line (issue #31, ellipsoids; core/centre_cut.hpp), one H100,
# about 4-6 minutes (at most 9: 120 s of unit cases, 400 s of runs), from the repository root on the
# device:
#   BIN=dir OUT=dir [N=16777216] [STEPS=40] jobs/gpu_ecut_check.sh
# (a dry run without a GPU: BACKEND=cpu N=65536 STEPS=10; its unit cases then skip: "FAILED: unit")
# (binaries: BIN, default .devbin/n, unpacked from .devbin/n.tar.xz when absent: contactgrid and
# contactgrid_tests of the CUDA build). It runs, in one call:
#  1. the CUDA unit cases of the skin and the shapes: EngineSkinCutTest/cuda* (every step of turning
#     ellipsoids, and of a scene of 9 ellipsoids in 10 whose spheres grow and whose semi-axes change,
#     = a fresh detection and = the CPU backend's rows, kept list and motion; a turn alone
#     rebuilds before the pair it brings together touches; changed semi-axes rebuild; under
#     CONTACTGRID_SKIN_CUT=0 the former list, the bounding spheres' count), EngineSkinTest/cuda*,
#     EngineSkinCuda*, EngineShapesTest*Cuda*, ResidentShapesTest/cuda*: all must pass, none skip;
#  2. jobs/gpu_rebuild_check.sh KIND=ellipsoids: N ellipsoids (semi-axes U[0.25, 1], aspect <= 1:4,
#     `generate --kind ellipsoids --contacts-per-body 6`, ~3.76 contacts a body), fp32, drift 0.01,
#     skin auto, STEPS steps, for VARIANTS now=- (the cut list, the default) and
#     old=CONTACTGRID_SKIN_CUT=0 (the former list of inflated bounding spheres), a fresh detection a
#     step (skin 0), each run's last step byte-identical (`contactgrid compare`) to a plain detect of
#     the final scene, every run's pair hash the same;
#  3. per run the builds' candidates (the trace's "build:" lines) and the summary's builds / reuses.
# VARIANTS="now=- ren0=CONTACTGRID_CUDA_RENUMBER=0 old=CONTACTGRID_SKIN_CUT=0" also runs a skin build
# without the bodies renumbered into cell order (pack.cuh: a fresh call of the cut keeps input order).
# What to expect (BENCHMARKS §33, H100, old): fresh 54.1 ms (pairs 26.2, narrow 21.7 over 64 M
# centre-cut candidates); old: a build 1.24x fresh, a reuse 35.2 ms over 137 M kept candidates, mean
# detection 0.749x fresh. now: a build's candidates about the fresh call's 64 M plus a skin's worth
# (well under old's 137 M), so a build <= ~1.0x fresh (its pairs stage keeps the bounding spheres'
# cells, the narrow screens fewer) and a reuse's narrow near the fresh call's ~22 ms: mean detection
# well under old's; the drift does not turn the bodies, so the builds come as often as old's (the
# skin tuner may pick another skin). Look at the table's "build/fresh", "mean detection/fresh",
# "reuse" and the candidates lines. Exits non-zero naming each failed check.
set -u
cd "$(dirname "$0")/.."
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt >/dev/null 2>&1
if [ -z "${BIN:-}" ]; then
  [ -d .devbin/n ] || tar xJf .devbin/n.tar.xz -C .devbin
  BIN=.devbin/n
fi
BIN=$(realpath "$BIN"); OUT=${OUT:-/tmp/out}; N=${N:-16777216}; STEPS=${STEPS:-40}
mkdir -p "$OUT"
failed=()
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
gtest_ok() {  # LOG: passed, nothing failed, no CUDA case skipped
  grep -q '^\[  PASSED  \]' "$1" && ! grep -q '^\[  FAILED  \]' "$1" && ! grep -q 'no CUDA device' "$1"
}

log "== 1. CUDA unit cases: skin cut, skin, shapes"
FILTER='EngineSkinCutTest/cuda*:EngineSkinTest/cuda*:EngineSkinCuda*:EngineShapesTest*Cuda*:ResidentShapesTest/cuda*'
timeout 120 "$BIN/contactgrid_tests" --gtest_color=no --gtest_filter="$FILTER" >"$OUT/unit.log" 2>&1
gtest_ok "$OUT/unit.log" || failed+=(unit)
echo "unit: $(grep -hE '^\[  (PASSED|FAILED)  \] [0-9]+ test' "$OUT/unit.log" | tr '\n' ' ')skipped $(grep -cE '^\[  SKIPPED \] .*\(' "$OUT/unit.log")"
grep -E '^\[  FAILED  \] [A-Za-z]' "$OUT/unit.log" | head -20

log "== 2. $N ellipsoids, drift 0.01, skin auto, $STEPS steps: now (cut) against old (CONTACTGRID_SKIN_CUT=0)"
SCRATCH=${SCRATCH:-/dev/shm} KIND=ellipsoids UNIT=0 N=$N STEPS=$STEPS ROUNDS=1 PROFILE=0 \
  VARIANTS="${VARIANTS:-now=- old=CONTACTGRID_SKIN_CUT=0}" BIN=$BIN OUT=$OUT/ellipsoids \
  timeout 400 jobs/gpu_rebuild_check.sh >"$OUT/rebuild.log" 2>&1 || failed+=(rebuild_check)
grep -vE '^  detect ' "$OUT/rebuild.log" | tail -40

log "== 3. candidates of each build (trace) and the summary's lists"
for v in ${VARIANTS:-now=- old=CONTACTGRID_SKIN_CUT=0}; do
  t=${v%%=*}1
  f=$OUT/ellipsoids/steps_$t.log
  [ -f "$f" ] || { echo "$t: no log"; continue; }
  echo "-- $t: $(grep -hoE 'candidate lists: [^;]*' "$f" | head -1)"
  echo "   builds' candidates: $(grep -E '^trace .* build:' "$f" | grep -oE 'candidates [0-9]+' | tr '\n' ' ')"
  echo "   a step (median): $(sed -nE '/^  interior/,/^  boundary/p' "$f" | grep -v boundary | tr -s ' ' | tr '\n' ' ')"
done
log "done"
if [ ${#failed[@]} -gt 0 ]; then echo "FAILED: ${failed[*]}"; exit 1; fi
echo "all checks passed"
