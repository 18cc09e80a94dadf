#!/usr/bin/env bash
# A/B of two builds of the core in the C++ profile driver (bench/profile_step.cpp): no Python
# in the timed loop, so the run-to-run noise is the machine's alone. Builds the driver from
# revision REF (default HEAD) and from the working tree, then runs them in paired alternation
# (old new | new old | ...) PAIRS times per configuration on the throughput packings of
# bench/throughput.py (generated and cached there; run it once first), and prints per
# configuration the median and minimum ms/step of each build, the median of the paired
# ratios new/old in particle-steps/s, and whether the two builds' checksums (bit patterns of
# the final state) agree.
#
#   bash bench/ab_driver.sh 1f3da9b 20
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
REF="${1:-HEAD}"
PAIRS="${2:-20}"
WORK="$ROOT/build/ab_driver"
mkdir -p "$WORK"
SHA=$(git -C "$ROOT" rev-parse --short=10 "$REF")
if [ ! -x "$WORK/old_$SHA" ]; then
  rm -rf "$WORK/src_$SHA" && mkdir -p "$WORK/src_$SHA"
  git -C "$ROOT" archive "$SHA" | tar -x -C "$WORK/src_$SHA"
  OUT="$WORK/old_$SHA" bash "$WORK/src_$SHA/bench/build_profile_step.sh" > /dev/null
fi
OUT="$WORK/new" bash "$ROOT/bench/build_profile_step.sh" > /dev/null
CACHE="$ROOT/results/bench_cache"
RAW="$WORK/runs_$SHA.txt"
: > "$RAW"
for n in 1000 10000; do
  csv=$(ls "$CACHE"/packing_n${n}_seed1_*.csv | head -n 1)
  side=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['box_hi'][0])" "${csv%.csv}.json")
  steps=$((3000000 / n)); warm=$((steps / 10))
  for t in 1 2; do
    for r in $(seq 1 "$PAIRS"); do
      order="old new"; [ $((r % 2)) = 0 ] && order="new old"
      for v in $order; do
        exe="$WORK/new"; [ "$v" = old ] && exe="$WORK/old_$SHA"
        line=$(OMP_NUM_THREADS=$t "$exe" "$csv" "$side" "$steps" "$warm" 2>&1 | tail -n 1)
        echo "$n $t $r $v $line" >> "$RAW"
      done
    done
  done
done
python3 - "$RAW" <<'PY'
import collections, re, statistics, sys
ms, cs = collections.defaultdict(dict), collections.defaultdict(set)
for line in open(sys.argv[1]):
    n, t, r, v = line.split()[:4]
    ms[(n, t, v)][r] = float(re.search(r"ms/step=([0-9.]+)", line).group(1))
    cs[(n, t)].add(re.search(r"checksum=([0-9a-f]+)", line).group(1))
print("| N | threads | old ms/step (median, min) | new ms/step (median, min) | new/old p-steps/s "
      "(median of pairs) | bitwise |")
print("|---|---|---|---|---|---|")
for n, t in sorted({(k[0], k[1]) for k in ms}, key=lambda x: (int(x[0]), x[1])):
    o, w = ms[(n, t, "old")], ms[(n, t, "new")]
    ratios = [o[r] / w[r] for r in o if r in w]
    print(f"| {n} | {t} | {statistics.median(o.values()):.4f}, {min(o.values()):.4f} | "
          f"{statistics.median(w.values()):.4f}, {min(w.values()):.4f} | "
          f"{statistics.median(ratios):.3f} | {'yes' if len(cs[(n, t)]) == 1 else 'no'} |")
PY
