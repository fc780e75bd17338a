#!/bin/bash
# hold9's A/B: base = detached worktree at a602461 (/work/wt/hold9-base), hold9 = this branch.
# Each command in its own process, the trees alternated, 2 pairs. Output: hold9_ab.txt.
PY=/work/main/.venv/bin/python
BASE=/work/wt/hold9-base
NEW=/work/wt/hold9
OUT=$NEW/docs/worklog/2026-11-26f/hold9_ab.txt
: > "$OUT"
for tree in $BASE $NEW; do   # warm numba's caches of both trees (not measured)
  (cd $tree && PYTHONPATH=$tree $PY bench/force_hold_payload.py --mass 565 --seconds 0.5 > /dev/null 2>&1)
  (cd $tree && PYTHONPATH=$tree $PY bench/preflight.py --repeats 1 --only gait > /dev/null 2>&1)
done
cpu() {  # tree, then the script and its arguments: the process's CPU time (s) around it
  local tree=$1; shift
  (cd "$tree" && PYTHONPATH=$tree $PY -c "
import runpy, sys, time
sys.argv = sys.argv[1:]
t = time.process_time()
try:
    runpy.run_path(sys.argv[0], run_name='__main__')
except SystemExit:
    pass
print('CPU_S', round(time.process_time() - t, 3), file=sys.stderr)
" "$@")
}
for pair in 1 2; do
  for tree in $BASE $NEW; do
    echo "== pair $pair tree $tree load $(cut -d' ' -f1-3 /proc/loadavg)" >> "$OUT"
    echo "-- bench/preflight.py --repeats 1 --only sine60,gait --json" >> "$OUT"
    (cd $tree && PYTHONPATH=$tree $PY bench/preflight.py --repeats 1 --only sine60,gait --json) >> "$OUT" 2>&1
    echo "-- bench/force_hold_payload.py --mass 565 --seconds 3 (CPU around it)" >> "$OUT"
    cpu $tree bench/force_hold_payload.py --mass 565 --seconds 3 >> "$OUT" 2>&1
  done
done
for tree in $BASE $NEW; do
  echo "== talus bench force --json, tree $tree load $(cut -d' ' -f1-3 /proc/loadavg)" >> "$OUT"
  (cd $tree && PYTHONPATH=$tree $PY -m talus bench force --json) > $NEW/docs/worklog/2026-11-26f/hold9_bench_force_$(basename $tree).json 2>&1
  echo "exit $?" >> "$OUT"
done
echo "== done $(date -u)" >> "$OUT"
