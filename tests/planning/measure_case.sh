#!/bin/sh
# Accuracy of the planning stage on a simulated case, through the CLI:
#   tests/planning/measure_case.sh CASE_DIR [BUILD_DIR] [OUT_DIR]
# 1. arpos plan CASE_DIR into a fresh store (time and map report),
# 2. room-marker positions against simulation.yaml (planning_eval --store),
# 3. arpos localize on room/, body_scan/ and every tracking/*, and
#    arpos evaluate against each groundtruth.txt (MTE/MRE, lost frames).
# Generate cases with e.g. `arpos simulate /tmp/case --profile xtion --seed 21`.
set -eu
CASE=$1
BUILD=${2:-build}
OUT=${3:-/tmp/arpos_measure_$(basename "$CASE")}
ARPOS=$BUILD/bin/arpos
mkdir -p "$OUT"
rm -f "$OUT/store.db"
echo "== arpos plan $CASE"
/usr/bin/time -f "plan: %e s wall, %U s user" "$ARPOS" plan "$CASE" --store "$OUT/store.db" > "$OUT/plan.txt" 2> "$OUT/plan_progress.txt" || { cat "$OUT/plan_progress.txt"; exit 1; }
grep -E "^markers|^frames|^landmarks|^residuals|^depth|^time|^warning" "$OUT/plan.txt" || true
tail -1 "$OUT/plan_progress.txt"
echo "== room markers against simulation.yaml"
NO_LOC=1 "$BUILD/bin/planning_eval" "$CASE" --store "$OUT/store.db" | sed -n '/^marker  corner/,$p'
for SEQ in "$CASE"/room "$CASE"/body_scan "$CASE"/tracking/*; do
  [ -d "$SEQ" ] || continue
  NAME=$(echo "$SEQ" | sed "s|^$CASE/||; s|/|_|g")
  echo "== $NAME"
  "$ARPOS" localize "$SEQ" --store "$OUT/store.db" --out "$OUT/$NAME.txt" --timings "$OUT/$NAME.csv" | head -1
  "$ARPOS" evaluate --gt "$SEQ/groundtruth.txt" --est "$OUT/$NAME.txt"
done
