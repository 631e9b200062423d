#!/bin/sh
# Every stage on cases with everything drawn at once, through the CLI:
#   tests/robustness/measure_sweep.sh FIRST LAST
# For each seed: arpos simulate --random-conditions with the camera profile
# (xtion, l515, d435 by seed % 3), the ArUco dictionary (six, by seed / 3), a
# sharpening camera (amount 0, 0, 0.8 or 1.5 by seed / 2), a lens distortion
# (every fifth seed), --hard (seeds 3, 10, 17, ... mod 7) and 90 or 150 room
# frames (even or odd seed) drawn from the seed, 60 body frames and one
# tracking sequence of 150; then arpos run-case (plan, session, tracking,
# each against the case's ground truth). Prints one line a seed: what was
# drawn, the exit status, the model pose at scan time and the tracking
# figures (with seq_00's frames reported `in`, truly in and `in` while
# truly out), or the first error. A case that fails is a finding, not skipped.
# Environment: BUILD (default build), ARPOS (default BUILD/bin/arpos; point
# it at a copy with its lib/ beside it when the build is being rebuilt),
# WORK (default /tmp/arpos_sweep). Cases are kept in WORK and reused when
# present; run-case runs again every time into a fresh store.
set -eu
[ $# -eq 2 ] || { echo "usage: measure_sweep.sh FIRST LAST" >&2; exit 2; }
BUILD=${BUILD:-build}
ARPOS=${ARPOS:-$BUILD/bin/arpos}
WORK=${WORK:-/tmp/arpos_sweep}
[ -x "$ARPOS" ] || { echo "measure_sweep: no $ARPOS (build the arpos target or set ARPOS)" >&2; exit 2; }
mkdir -p "$WORK"
set -- $(seq "$1" "$2")
for s in "$@"; do
  case $((s % 3)) in 0) p=xtion ;; 1) p=l515 ;; *) p=d435 ;; esac
  case $(((s / 3) % 6)) in
    0) d=DICT_4X4_250 ;; 1) d=DICT_5X5_250 ;; 2) d=DICT_6X6_250 ;;
    3) d=DICT_APRILTAG_36h11 ;; 4) d=DICT_ARUCO_ORIGINAL ;; *) d=DICT_4X4_1000 ;;
  esac
  case $(((s / 2) % 4)) in 2) sh=0.8 ;; 3) sh=1.5 ;; *) sh=0 ;; esac
  extra=""
  [ "$sh" != 0 ] && extra="$extra --sharpen $sh"
  [ $((s % 5)) -eq 0 ] && extra="$extra --distortion 0.12,-0.3,0.001,-0.001,0.1"
  [ $((s % 7)) -eq 3 ] && extra="$extra --hard"
  rf=$((s % 2 == 0 ? 90 : 150))
  n=$WORK/s$s
  if [ ! -f "$n/simulation.yaml" ]; then
    # shellcheck disable=SC2086
    if ! "$ARPOS" simulate "$n" --profile $p --seed "$s" --random-conditions --dictionary $d $extra \
        --frames room=$rf,body=60,tracking=150 --tracking-sequences 1 > "$n.sim.txt" 2>&1; then
      echo "s$s $p $d: simulate FAILED ($(tail -1 "$n.sim.txt"))"
      continue
    fi
  fi
  rm -rf "$n.db" "$n.out"
  rc=0
  "$ARPOS" run-case "$n" --store "$n.db" --out "$n.out" > "$n.run.txt" 2>&1 || rc=$?
  drawn=$(grep -E '^  (origin_placement|origin_visibility|response):' "$n/simulation.yaml" | awk '{printf "%s ", $2}')
  model=$(grep -o 'model pose at scan time vs body_groundtruth.txt: [0-9.]* mm, [0-9.]* deg' "$n.run.txt" | awk '{print $8, $10}')
  track=$(grep -o 'MTE [0-9.]* mm, MRE [0-9.]* deg ([^)]*), [0-9.]* % lost' "$n.run.txt" | head -1)
  err=$(grep -m1 -E 'error|internal' "$n.run.txt" || true)
  # `in` against the truth (seq_00 ends held within tolerance): reported in,
  # truly in, reported in while truly out (must be 0).
  ins=""
  if [ -f "$n.out/seq_00/corrections.csv" ]; then
    ins=$("$ARPOS" evaluate --corrections "$n.out/seq_00/corrections.csv" \
        --gt "$n/tracking/seq_00/body_groundtruth.txt" --target "$n/target_pose.txt" 2>/dev/null |
      awk '/^reported: in/ {r = $3 + 0} /^truly/ {t = $9 + 0} /^reported in while truly out/ {w = $6 + 0}
           END {if (r != "") printf "in %s, truly in %s, in while out %s", r, t, w}' || true)
  fi
  echo "s$s $p $d room=$rf$extra | $drawn| exit $rc | model ${model:-n/a} (mm, deg) | ${track:-no tracking figures} ${ins:+| $ins} ${err:+| $err}"
done
