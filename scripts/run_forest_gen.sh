#!/usr/bin/env bash
# Runs bench_replan on every forest_gen map (octomaps/forestN.bt with its tasks in
# start_and_end.csv) for every method, and sums up each method over all maps.
#   run_forest_gen.sh BENCH_REPLAN FOREST_GEN_DIR OUT_DIR
set -euo pipefail
bin=$1 data=$2 out=$3
[ -f "$data/start_and_end.csv" ] || { echo "no forest_gen data in $data" >&2; exit 1; }
echo "| method | tasks | success | total ms median | p95 |"
echo "|---|---|---|---|---|"
for method in proposed gto gto_restart astar_pgo; do
  for map in "$data"/octomaps/forest*.bt; do
    id=$(basename "$map" .bt); id=${id#forest}
    dir="$out/$method/map$id"
    mkdir -p "$dir"
    "$bin" --map "$map" --tasks "$data/start_and_end.csv" --map-id "$id" --method "$method" --out "$dir" > "$dir/log.txt" 2>/dev/null
  done
  # Sum over maps: tasks, solved, and the time distribution.
  cat "$out/$method"/map*/summary.csv | grep -v '^trial' > "$out/$method/all.csv" || true
  head -1 "$(ls "$out/$method"/map*/summary.csv | head -1)" > "$out/$method/header.csv"
  /usr/bin/python3 - "$method" "$out/$method/all.csv" <<'PY'
import sys, statistics
method, path = sys.argv[1], sys.argv[2]
rows = [l.strip().split(',') for l in open(path) if l.strip()]
ok = [r for r in rows if r[2] == '1']
t = sorted(float(r[5]) for r in rows)
p95 = t[min(len(t) - 1, int(0.95 * (len(t) - 1) + 0.5))] if t else 0.0
print('| %s | %d | %.2f%% | %.3f | %.3f |' % (method, len(rows), 100.0 * len(ok) / max(1, len(rows)),
      statistics.median(t) if t else 0.0, p95))
PY
done
# Where the proposed method's time goes, over every map: the per-call phases (bench_replan's
# summary.csv columns after num_paths), median and p95.
/usr/bin/python3 - "$out/proposed/header.csv" "$out/proposed/all.csv" <<'PY'
import csv, sys, statistics
names = next(csv.reader(open(sys.argv[1])))[7:]
rows = [l.strip().split(',') for l in open(sys.argv[2]) if l.strip()]
def pct(v, q):
    v = sorted(v)
    return v[min(len(v) - 1, int(q * (len(v) - 1) + 0.5))] if v else 0.0
print('\n| proposed, phase per call | median | p95 | mean |\n|---|---|---|---|')
for k, name in enumerate(names):
    v = [float(r[7 + k]) for r in rows if len(r) > 7 + k]
    print('| %s | %.3f | %.3f | %.3f |' % (name, pct(v, 0.5), pct(v, 0.95), sum(v) / max(1, len(v))))
PY
