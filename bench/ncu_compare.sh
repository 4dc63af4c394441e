#!/usr/bin/env bash
# Hardware counters of weft's and warp-lang's saxpy and integration kernels at one size (default
# 1e7), side by side: Nsight Compute over bench/prof_kernel_ncu.py for each library, then one
# table (the median of each metric over the launches). On the GPU machine, after scripts/gpu-run's
# setup (WEFT_DAEMON) and with warp-lang on PYTHONPATH. Usage: bash bench/ncu_compare.sh [n] [outdir]
set -uo pipefail
n=${1:-1e7}
out=${2:-/tmp/ncu-compare}
mkdir -p "$out"
metrics=gpu__time_duration.sum,dram__bytes_read.sum,dram__bytes_write.sum,\
dram__throughput.avg.pct_of_peak_sustained_elapsed,sm__warps_active.avg.pct_of_peak_sustained_active,\
smsp__inst_executed.sum,launch__registers_per_thread,launch__grid_size,launch__block_size,\
lts__t_sectors_op_read.sum,lts__t_sectors_op_write.sum,sm__cycles_elapsed.avg,\
smsp__warp_issue_stalled_long_scoreboard_per_warp_active.pct,smsp__warp_issue_stalled_lg_throttle_per_warp_active.pct
for lib in weft warp; do
  ncu --target-processes all --clock-control none -k 'regex:saxpy|integrate' --metrics "$metrics" --csv \
    python3 bench/prof_kernel_ncu.py --lib "$lib" --n "$n" >"$out/ncu-$lib.csv" 2>"$out/ncu-$lib.err"
  echo "ncu $lib: exit $?"
  tail -3 "$out/ncu-$lib.err"
done
python3 - "$out" <<'PY'
import csv, io, statistics, sys
from collections import defaultdict
out = sys.argv[1]
vals = defaultdict(list)   # (kernel kind, metric, lib) -> values
metrics = []
for lib in ("weft", "warp"):
    text = open(f"{out}/ncu-{lib}.csv").read()
    start = text.find('"ID"')
    if start < 0:
        print(f"{lib}: no ncu rows"); continue
    for row in csv.DictReader(io.StringIO(text[start:])):
        kind = "saxpy" if "saxpy" in row["Kernel Name"] else "integrate"
        if "backward" in row["Kernel Name"]: continue
        m = row["Metric Name"]
        if m not in metrics: metrics.append(m)
        try: vals[(kind, m, lib)].append(float(row["Metric Value"].replace(",", "")))
        except ValueError: pass
        vals[(kind, "unit:" + m, lib)] = row["Metric Unit"]
for kind in ("saxpy", "integrate"):
    print(f"\n{kind}: metric | weft | warp-lang")
    for m in metrics:
        w = vals.get((kind, m, "weft")); r = vals.get((kind, m, "warp"))
        f = lambda v: f"{statistics.median(v):.4g}" if v else "n/a"
        print(f"  {m} [{vals.get((kind, 'unit:' + m, 'weft'), '')}] | {f(w)} | {f(r)}")
PY
