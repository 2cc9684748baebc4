#!/usr/bin/env python3
"""Nsight Compute's raw CSV (--csv --log-file) summed by kernel name: total time, launches, time a
launch and, where the CSV has it, the mean DRAM throughput (% of peak).
  ncu_sum.py FILE.csv [TOP=24]"""
import collections
import csv
import sys

rows = list(csv.reader(open(sys.argv[1], errors="replace")))
top = int(sys.argv[2]) if len(sys.argv) > 2 else 24
hdr = next((i for i, r in enumerate(rows) if "Metric Name" in r), None)
if hdr is None:
    print("no ncu rows")
    sys.exit()
h = rows[hdr]
k, m, v = h.index("Kernel Name"), h.index("Metric Name"), h.index("Metric Value")
tot, cnt, dram = collections.defaultdict(float), collections.Counter(), collections.defaultdict(list)
for r in rows[hdr + 1:]:
    if len(r) <= v:
        continue
    try:
        val = float(r[v].replace(",", ""))
    except ValueError:
        continue
    name = r[k].split("(")[0][:90]
    if r[m] == "gpu__time_duration.sum":
        tot[name] += val
        cnt[name] += 1
    elif r[m].startswith("dram__"):
        dram[name].append(val)
all_ = sum(tot.values()) or 1.0
for n, t in sorted(tot.items(), key=lambda x: -x[1])[:top]:
    d = dram[n]
    share = f" dram {sum(d) / len(d):5.1f}%" if d else ""
    print(f"{t / 1e6:9.3f} ms {100 * t / all_:5.1f}% x{cnt[n]:<4} {t / 1e6 / cnt[n]:8.3f} ms each{share}  {n}")
print(f"total {sum(tot.values()) / 1e6:.3f} ms over {sum(cnt.values())} launches")
