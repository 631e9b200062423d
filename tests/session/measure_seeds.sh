#!/bin/sh
# Session-stage accuracy over many seeds, through the CLI:
#   tests/session/measure_seeds.sh [FIRST LAST] [PROFILE] [BUILD_DIR] [WORK_DIR]
# For each seed: arpos simulate (room=60, body=60, one 1-frame tracking
# sequence), arpos plan, arpos session --out, then arpos evaluate of the model
# pose at scan time against body_scan/body_groundtruth.txt. Prints one line a
# seed (error, alignment status, session wall time) and a summary: mean,
# median, max, and how many are right (within 5 mm / 1 deg: a wrong
# alignment lands centimetres off). Cases are kept in
# WORK_DIR (default /tmp/arpos_seeds_PROFILE) and reused when present.
set -eu
FIRST=${1:-1}
LAST=${2:-20}
PROFILE=${3:-xtion}
BUILD=${4:-build}
WORK=${5:-/tmp/arpos_seeds_$PROFILE}
ARPOS=$BUILD/bin/arpos
mkdir -p "$WORK"
: > "$WORK/summary.txt"
for s in $(seq "$FIRST" "$LAST"); do
  C=$WORK/c$s
  if [ ! -f "$C/simulation.yaml" ]; then
    rm -rf "$C"
    "$ARPOS" simulate "$C" --profile "$PROFILE" --seed "$s" --frames room=60,body=60,tracking=1 \
      --tracking-sequences 1 > /dev/null 2>&1
  fi
  rm -rf "$C.db" "$C.out"
  "$ARPOS" plan "$C" --store "$C.db" > /dev/null 2>&1
  start=$(date +%s.%N)
  "$ARPOS" session "$C" --store "$C.db" --out "$C.out" > "$C.session.txt" 2>&1 || true
  end=$(date +%s.%N)
  status=$(sed -n 's/^alignment (\([^)]*\)).*/\1/p' "$C.session.txt")
  if [ -f "$C.out/model_pose.txt" ]; then
    "$ARPOS" evaluate --gt "$C/body_scan/body_groundtruth.txt" --est "$C.out/model_pose.txt" --json > "$C.eval.json"
    t=$(sed -n 's/.*"translation_mm": *{[^}]*"mean": *\([0-9.e+-]*\).*/\1/p' "$C.eval.json")
    r=$(sed -n 's/.*"rotation_deg": *{[^}]*"mean": *\([0-9.e+-]*\).*/\1/p' "$C.eval.json")
  else
    t=nan r=nan status="failed: $(tail -1 "$C.session.txt")"
  fi
  line=$(awk -v s="$s" -v t="$t" -v r="$r" -v a="$start" -v b="$end" -v st="$status" \
    'BEGIN { printf "seed %d: %s mm %s deg, %.1f s, %s", s, t, r, b - a, st }')
  echo "$line"
  echo "$t $r" >> "$WORK/summary.txt"
done
sort -n "$WORK/summary.txt" | awk '
  { t[NR] = $1; r[NR] = $2; st += $1; sr += $2; if ($1 < 5 && $2 < 1) ok++; if ($2 > rm) rm = $2 }
  END { if (NR == 0) exit; m = (NR % 2) ? t[(NR + 1) / 2] : (t[NR / 2] + t[NR / 2 + 1]) / 2;
        printf "%d seeds: translation mean %.2f mm, median %.2f, max %.2f; rotation mean %.3f deg, max %.3f; right (within 5 mm / 1 deg): %d of %d\n",
               NR, st / NR, m, t[NR], sr / NR, rm, ok, NR }'
