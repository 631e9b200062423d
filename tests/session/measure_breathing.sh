#!/bin/sh
# Model pose at scan time on default scenes with depth bias and breathing:
#   tests/session/measure_breathing.sh FIRST LAST [PROFILE]
# For each seed: arpos simulate (room=120, body=90, one 1-frame tracking
# sequence; default scene) with the camera responses in turn (srgb, linear,
# gamma2.6, scurve by seed mod 4) and, drawn from the seed, a depth scale
# error of +-0.4 %, a 1-4 mm depth error field, flying pixels and 3-6 mm of
# breathing; then arpos plan, arpos session --out and arpos evaluate of
# model_pose.txt against body_scan/body_groundtruth.txt. One line a seed:
# the conditions, the error, the scan's placement and what the session said
# about the surface's motion. Environment: ARPOS (default build/bin/arpos),
# WORK (default /tmp/arpos_breathing_PROFILE), FRAMES (default
# room=120,body=90,tracking=1), and BR / SC / FI to force the breathing (mm),
# depth scale error and field (mm); FLY= (empty) leaves out flying pixels.
# Cases are kept in WORK and not simulated again; plan and session run again.
set -u
FIRST=$1
LAST=$2
PROFILE=${3:-xtion}
ARPOS=${ARPOS:-build/bin/arpos}
WORK=${WORK:-/tmp/arpos_breathing_$PROFILE}
FRAMES=${FRAMES:-room=120,body=90,tracking=1}
[ -x "$ARPOS" ] || { echo "measure_breathing: no $ARPOS (build the arpos target or set ARPOS)" >&2; exit 2; }
mkdir -p "$WORK"
for s in $(seq "$FIRST" "$LAST"); do
  C=$WORK/c$s
  resp=$(echo "srgb linear gamma2.6 scurve" | cut -d' ' -f$((s % 4 + 1)))
  sc=${SC:-$(awk -v s="$s" 'BEGIN { srand(s); printf "%.4f", (rand() - 0.5) * 0.008 }')}
  fi=${FI:-$(awk -v s="$s" 'BEGIN { srand(s * 7 + 1); printf "%.1f", 1 + 3 * rand() }')}
  br=${BR:-$(awk -v s="$s" 'BEGIN { srand(s * 13 + 2); printf "%.1f", 3 + 3 * rand() }')}
  if [ ! -f "$C/simulation.yaml" ]; then
    # shellcheck disable=SC2086
    "$ARPOS" simulate "$C" --profile "$PROFILE" --seed "$s" --frames "$FRAMES" --tracking-sequences 1 \
      --response "$resp" --depth-scale-error "$sc" --depth-field-mm "$fi" ${FLY---flying-pixels} \
      --breathing-mm "$br" > "$C.simulate.txt" 2>&1 || { echo "seed $s: FAILED simulate"; continue; }
  fi
  rm -rf "$C.db" "$C.out"
  if ! "$ARPOS" plan "$C" --store "$C.db" > "$C.plan.txt" 2>&1; then
    echo "seed $s $resp: FAILED plan: $(tail -1 "$C.plan.txt")"
    continue
  fi
  if ! "$ARPOS" session "$C" --store "$C.db" --out "$C.out" > "$C.session.txt" 2>&1; then
    echo "seed $s $resp: FAILED session: $(tail -1 "$C.session.txt")"
    continue
  fi
  "$ARPOS" evaluate --gt "$C/body_scan/body_groundtruth.txt" --est "$C.out/model_pose.txt" --json > "$C.eval.json"
  t=$(sed -n 's/.*"translation_mm": *{[^}]*"mean": *\([0-9.e+-]*\).*/\1/p' "$C.eval.json")
  r=$(sed -n 's/.*"rotation_deg": *{[^}]*"mean": *\([0-9.e+-]*\).*/\1/p' "$C.eval.json")
  place=$(grep -o "placed in the room from [0-9]* frames in [0-9]* run(s), [0-9.]* mm" "$C.session.txt" | head -1)
  motion=$(grep -o "[0-9]* of [0-9]* surface patches moved\|no part of the surface moved\|surface motion not measured" \
    "$C.session.txt" | head -1)
  echo "seed $s $resp scale $sc field $fi breathing $br: $t mm $r deg | $place | $motion"
done
