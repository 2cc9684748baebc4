#!/usr/bin/env bash
# Per-kernel durations (Nsight Compute, clocks left alone) of the workloads whose targets are still open:
#   BIN=dir OUT=dir jobs/gpu_profile.sh [simulate20] [simulate24] [steps24] [host20]
# simulate20/24: a granular pour at 6 contacts a body (2^20, 2^24), a window of launches after warm-up;
# steps24: `detect --steps` on 2^24 spheres drifting 1 % of r_max a step, skin auto (reuse and rebuild);
# host20: the host path (host arrays → host contacts) at 2^20 under ncu, kernels only.
# Each writes <name>.csv (ncu's raw CSV: kernel, grid, duration, DRAM and SM throughput), <name>.sum.txt
# (time per kernel name over the window) and <name>.txt (the run's own stage times without ncu), all in
# $OUT/profile.tgz.
set -u
cd "$(dirname "$0")/.."
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt >/dev/null 2>&1
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; CG=$BIN/contactgrid
W=${SCRATCH:-/dev/shm}/cg_profile; mkdir -p "$W" "$OUT"
NCU=$(command -v ncu || ls /opt/nvidia/nsight-compute/*/ncu 2>/dev/null | head -1)
echo "ncu: $NCU"
metrics=gpu__time_duration.sum,dram__throughput.avg.pct_of_peak_sustained_elapsed,sm__throughput.avg.pct_of_peak_sustained_elapsed,launch__grid_size,launch__registers_per_thread
# EXTRA_METRICS: more ncu metrics for the raw CSV (e.g. occupancy, L2 hit rate, DRAM bytes)
metrics=$metrics${EXTRA_METRICS:+,$EXTRA_METRICS}
prof() {  # name skip count command...
  local name=$1 skip=$2 count=$3; shift 3
  echo "== $name: $*"
  timeout 170 "$NCU" --clock-control none --metrics "$metrics" --launch-skip "$skip" --launch-count "$count" --csv \
    --log-file "$OUT/$name.csv" "$@" >"$OUT/$name.out" 2>&1 || echo "ncu $name rc=$?"
  # total duration per kernel name over the window
  python3 jobs/ncu_sum.py "$OUT/$name.csv" 40 | tee "$OUT/$name.sum.txt"
}
pour() { "$CG" generate "$W/$1.h5" --kind pour -n "$2" --rlow 0.00495 --rhigh 0.005 --pour-spacing 1.97 --seed 5 -q; }
parts=("$@"); [ ${#parts[@]} -eq 0 ] && parts=(simulate20 simulate24 steps24 host20)
for part in "${parts[@]}"; do
  case $part in
    simulate20)
      pour p20 $((1 << 20))
      "$CG" simulate "$W/p20.h5" -o "$W/r20" --steps 120 --output-every 120 --backend cuda --precision fp32 --no-plot \
        --stage-times >"$OUT/simulate20.txt" 2>&1
      rm -rf "$W/r20"
      prof simulate20 200 500 "$CG" simulate "$W/p20.h5" -o "$W/r20" --steps 60 --output-every 60 --backend cuda \
        --precision fp32 --no-plot
      rm -rf "$W/r20" ;;
    simulate24)
      pour p24 $((1 << 24))
      "$CG" simulate "$W/p24.h5" -o "$W/r24" --steps 30 --output-every 30 --backend cuda --precision fp32 --no-plot \
        --stage-times >"$OUT/simulate24.txt" 2>&1
      rm -rf "$W/r24"
      prof simulate24 150 300 "$CG" simulate "$W/p24.h5" -o "$W/r24" --steps 20 --output-every 20 --backend cuda \
        --precision fp32 --no-plot
      rm -rf "$W/r24" "$W/p24.h5" ;;
    steps24)
      "$CG" generate "$W/s24.h5" -n $((1 << 24)) --seed 24 --contacts-per-body 6 -q
      "$CG" detect "$W/s24.h5" -o "$W/o.h5" --backend cuda --precision fp32 --steps 40 --drift 0.01 --skin auto \
        >"$OUT/steps24.txt" 2>&1
      prof steps24 100 500 "$CG" detect "$W/s24.h5" -o "$W/o.h5" --backend cuda --precision fp32 --steps 16 \
        --drift 0.01 --skin auto
      rm -f "$W/s24.h5" "$W/o.h5" ;;
    host20)
      "$BIN/contactgrid_cuda_bench" 20 20 1 10 auto spheres >"$OUT/host20.txt" 2>&1
      prof host20 0 400 "$BIN/contactgrid_cuda_bench" 20 20 1 3 auto spheres ;;
  esac
done
rm -rf "$W"
tar czf "$OUT/profile.tgz" -C "$OUT" --exclude profile.tgz . && find "$OUT" -type f ! -name profile.tgz -delete
