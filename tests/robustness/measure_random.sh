#!/bin/sh
# Planning and session on scenes this project's pipeline was not tuned on,
# through the CLI:
#   tests/robustness/measure_random.sh [FIRST LAST] [PROFILE] [--response NAME] [SIMULATE FLAGS...]
# For each seed: arpos simulate --random-conditions (room=60, body=60, one
# 1-frame tracking sequence; the seed draws the origin marker's placement and
# visibility, room markers, room, walk, camera response, auto exposure, depth
# bias and breathing: src/simulation/conditions.h), arpos plan, arpos session
# --out, then arpos evaluate of the model pose at scan time against
# body_scan/body_groundtruth.txt. Prints one line a seed with the drawn
# conditions and the result (mm, deg, or FAILED with the stage and its
# message: a failed plan or session is a finding, not skipped), then a
# summary: overall and per condition (response, auto exposure, origin
# placement and visibility, depth bias, breathing, walk): seeds, failures,
# mean and max error of the rest, and how many are right (within 5 mm /
# 1 deg).
#   --response NAME   forces one camera response for every seed (srgb, linear,
#                     gamma2.6, scurve); the other conditions stay as drawn.
# Other flags go to arpos simulate as they are (e.g. --breathing-mm 0,
# --depth-scale-error 0, --auto-exposure). Environment: BUILD (default
# build), WORK (default /tmp/arpos_random_PROFILE[_FLAGS]). Cases are kept in
# WORK and reused when simulated with the same flags; plan and session run
# again every time.
set -eu
FIRST=1
LAST=20
PROFILE=xtion
case "${1:-}" in [0-9]*) FIRST=$1; shift ;; esac
case "${1:-}" in [0-9]*) LAST=$1; shift ;; esac
case "${1:-}" in ""|-*) ;; *) PROFILE=$1; shift ;; esac
EXTRA="$*"
BUILD=${BUILD:-build}
TAG=$(printf '%s' "$EXTRA" | tr -c 'A-Za-z0-9.=' '_' | sed 's/__*/_/g; s/^_//; s/_$//')
WORK=${WORK:-/tmp/arpos_random_$PROFILE${TAG:+_$TAG}}
ARPOS=$BUILD/bin/arpos
[ -x "$ARPOS" ] || { echo "measure_random: no $ARPOS (build the arpos target)" >&2; exit 2; }
mkdir -p "$WORK"
RESULTS=$WORK/results.tsv
: > "$RESULTS"

# The value of KEY in the conditions: block of simulation.yaml.
condition() {
  awk -v key="$2:" '/^conditions:/ { inside = 1; next } /^[^ ]/ { inside = 0 }
                    inside && $1 == key { sub(/^ *[^:]*: */, ""); print; exit }' "$1/simulation.yaml"
}
# The last line of a log without progress lines, shortened.
last_message() {
  grep -v '^\[ *[0-9]*%\]' "$1" | sed '/^ *$/d' | tail -1 | cut -c1-160
}

for s in $(seq "$FIRST" "$LAST"); do
  C=$WORK/c$s
  start=$(date +%s.%N)
  if [ ! -f "$C/simulation.yaml" ] || [ "$(cat "$C.flags" 2>/dev/null)" != "$PROFILE $EXTRA" ]; then
    rm -rf "$C" "$C.flags"
    # shellcheck disable=SC2086
    if ! "$ARPOS" simulate "$C" --profile "$PROFILE" --seed "$s" --random-conditions \
        --frames room=60,body=60,tracking=1 --tracking-sequences 1 $EXTRA > "$C.simulate.txt" 2>&1; then
      echo "seed $s: FAILED simulate: $(last_message "$C.simulate.txt")"
      printf '%s\tsimulate\tfailed\tnan\tnan\t-\t-\t-\t-\t-\t-\t-\t-\t-\n' "$s" >> "$RESULTS"
      continue
    fi
    echo "$PROFILE $EXTRA" > "$C.flags"
  fi
  response=$(condition "$C" response)
  ae=$(condition "$C" auto_exposure)
  placement=$(condition "$C" origin_placement)
  surface=$(condition "$C" origin_surface)
  visibility=$(condition "$C" origin_visibility)
  seen=$(condition "$C" origin_visible_frames)
  frames=$(condition "$C" room_frames)
  side=$(condition "$C" origin_median_side_px)
  angle=$(condition "$C" origin_median_view_angle_deg)
  markers=$(condition "$C" room_marker_count)
  size=$(condition "$C" room_marker_size_m)
  walk=$(condition "$C" room_walk)
  scale=$(condition "$C" depth_scale_error)
  field=$(condition "$C" depth_field_mm)
  flying=$(condition "$C" flying_pixels)
  breathing=$(condition "$C" breathing_mm)
  conditions=$(awk -v r="$response" -v ae="$ae" -v pl="$placement" -v su="$surface" -v vi="$visibility" \
    -v seen="$seen" -v fr="$frames" -v px="$side" -v an="$angle" -v mk="$markers" -v sz="$size" \
    -v wk="$walk" -v sc="$scale" -v fi="$field" -v fl="$flying" -v br="$breathing" 'BEGIN {
      printf "%-8s%s origin %s/%s %s/%s %.0fpx %.0fdeg, %d markers %.2fm %s, depth %+.2f%% field %.1fmm%s, breathing %.1fmm",
        r, (ae == "true" ? "+AE" : "   "), (pl == "wall" ? su : pl), vi, seen, fr, px, an, mk, sz, wk,
        100 * sc, fi, (fl == "true" ? " flying" : ""), br }')

  rm -rf "$C.db" "$C.out"
  stage=ok
  if ! "$ARPOS" plan "$C" --store "$C.db" > "$C.plan.txt" 2>&1; then
    stage=plan
  elif ! "$ARPOS" session "$C" --store "$C.db" --out "$C.out" > "$C.session.txt" 2>&1 ||
       [ ! -f "$C.out/model_pose.txt" ]; then
    stage=session
  fi
  end=$(date +%s.%N)
  if [ "$stage" = ok ]; then
    "$ARPOS" evaluate --gt "$C/body_scan/body_groundtruth.txt" --est "$C.out/model_pose.txt" --json > "$C.eval.json"
    t=$(sed -n 's/.*"translation_mm": *{[^}]*"mean": *\([0-9.e+-]*\).*/\1/p' "$C.eval.json")
    r=$(sed -n 's/.*"rotation_deg": *{[^}]*"mean": *\([0-9.e+-]*\).*/\1/p' "$C.eval.json")
    result=$(awk -v t="$t" -v r="$r" 'BEGIN { printf "%.2f mm %.3f deg", t, r }')
  else
    t=nan r=nan
    result="FAILED $stage: $(last_message "$C.$stage.txt")"
  fi
  awk -v s="$s" -v c="$conditions" -v res="$result" -v a="$start" -v b="$end" \
    'BEGIN { printf "seed %d: %s -> %s (%.0f s)\n", s, c, res, b - a }'
  depth_class=$(awk -v sc="$scale" -v fi="$field" -v fl="$flying" 'BEGIN {
      a = sc < 0 ? -sc : sc; s = (a == 0 ? "none" : a < 0.003 ? "small" : "large");
      printf "scale_%s,field_%s,flying_%s", s, (fi > 0 ? "yes" : "no"), fl }')
  breathing_class=$(awk -v br="$breathing" 'BEGIN { print (br > 0 ? "yes" : "none") }')
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$s" "$stage" \
    "$([ "$stage" = ok ] && echo ok || echo failed)" "$t" "$r" "$response" "$ae" "$placement" \
    "$visibility" "$depth_class" "$breathing_class" "$walk" "$seen" "$surface" >> "$RESULTS"
done

# Summary: overall, then per condition. Columns of results.tsv: seed, stage
# (ok | simulate | plan | session), ok/failed, mm, deg, response, auto
# exposure, origin placement, origin visibility, depth bias, breathing, walk,
# origin frames seen, origin surface.
awk -F '\t' '
  function add(group, value) {
    key = group " " value
    if (!(key in n)) { order[++keys] = key }
    n[key]++
    if ($3 == "ok") {
      ok[key]++; st[key] += $4; sr[key] += $5
      if ($4 > mt[key]) mt[key] = $4
      if ($5 > mr[key]) mr[key] = $5
      if ($4 < 5 && $5 < 1) right[key]++
    } else {
      failed[key]++; stages[key, $2]++
    }
  }
  function show(key) {
    line = sprintf("%-34s %2d seeds: %2d failed", key, n[key], failed[key] + 0)
    if (failed[key] > 0) {
      sep = " ("
      split("simulate plan session", names, " ")
      for (j = 1; j <= 3; ++j) {
        if (stages[key, names[j]] > 0) { line = line sep stages[key, names[j]] " " names[j]; sep = ", " }
      }
      line = line ")"
    }
    if (ok[key] > 0) {
      line = line sprintf("; %d ran: mean %.2f mm %.3f deg, max %.2f mm %.3f deg; right (5 mm / 1 deg) %d of %d",
                          ok[key], st[key] / ok[key], sr[key] / ok[key], mt[key], mr[key], right[key] + 0, n[key])
    }
    # Sorted by condition, all seeds first.
    print (key == "all seeds" ? " " : "") key "\t" line | "sort -t \"\t\" -k1,1 | cut -f2-"
  }
  {
    add("all", "seeds")
    add("response", $6)
    add("auto_exposure", $7)
    add("origin_placement", $8)
    add("origin_visibility", $9)
    split($10, d, ",")
    add("depth", d[1]); add("depth", d[2]); add("depth", d[3])
    add("breathing", $11)
    add("walk", $12)
  }
  END {
    if (NR == 0) exit
    print ""
    print "summary (errors: model pose at scan time against body_groundtruth.txt; failed: the stage that stopped):"
    fflush()
    for (i = 1; i <= keys; ++i) show(order[i])
    close("sort -t \"\t\" -k1,1 | cut -f2-")
  }' "$RESULTS"
