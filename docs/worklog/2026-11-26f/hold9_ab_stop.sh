#!/bin/bash
# The force stop's cycle cost, A/B: hold9's bench/force_hold_payload.py (its stop_cycle_cpu_us)
# on the base tree's code (PYTHONPATH=a602461's detached worktree) and on hold9's, alternated,
# 3 pairs, each in its own process. Output: hold9_ab_stop.txt.
PY=/work/main/.venv/bin/python
NEW=/work/wt/hold9
OUT=$NEW/docs/worklog/2026-11-26f/hold9_ab_stop.txt
: > "$OUT"
for pair in 1 2 3; do
  for tree in /work/wt/hold9-base $NEW; do
    echo "== pair $pair tree $tree load $(cut -d' ' -f1-3 /proc/loadavg)" >> "$OUT"
    (cd $tree && PYTHONPATH=$tree $PY $NEW/bench/force_hold_payload.py --mass 565 --seconds 3) >> "$OUT" 2>&1
  done
done
