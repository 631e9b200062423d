#!/bin/sh
# Tracking accuracy, safety and time over seeds and conditions, through the CLI:
#   tests/tracking/measure_tracking.sh [SPEC...]
# SPEC is PROFILE:SEEDS[:SIMULATE FLAGS], SEEDS a seed or a range FIRST-LAST;
# the flags are arpos simulate options, space separated in one argument. The
# default list:
#   xtion:41-43  l515:44  "xtion:45:--hard"  "xtion:46-50:--random-conditions"
#   "xtion:41-43:--room-texture plain"
# For each seed: arpos simulate --tracking-sequences 2 (default frames unless
# FRAMES is set), arpos plan, arpos session, then arpos track of every
# tracking/seq_NN with --out, arpos evaluate of poses.txt against the
# sequence's body_groundtruth.txt (MTE, MRE, medians, p95, lost %) and arpos
# evaluate --corrections of corrections.csv against it and target_pose.txt
# (frames reported in / out / lost, truly in / out, reported in while truly
# out: must be 0, reported out while truly in; error of the shift). Prints
# one line a sequence and writes them to WORK/results.tsv, then a summary per
# condition (profile and flags): seeds, failures, mean and max of the
# figures, the safety count summed. A seed whose simulate, plan, session or
# track fails is a failure: reported with the stage and its message, not
# skipped.
# Environment: BUILD (default build), ARPOS (default BUILD/bin/arpos; point it
# at a copy of the binary when the build folder is being rebuilt), WORK
# (default /tmp/arpos_tracking), FRAMES (e.g. room=200,body=120,tracking=90;
# default: the simulator's), SEQUENCES (default 2), TRACK_FLAGS (extra
# options for arpos track, e.g. --sequential), TOLERANCE_MM / TOLERANCE_DEG
# (default 2 / 1, for both track and evaluate). Cases are kept in WORK and
# reused when simulated with the same flags (a case folder with its
# simulation.yaml is not simulated again); plan, session and track run again
# every time. Exit status 1 when a seed failed or a frame read `in` while
# truly out.
set -eu
BUILD=${BUILD:-build}
ARPOS=${ARPOS:-$BUILD/bin/arpos}
WORK=${WORK:-/tmp/arpos_tracking}
SEQUENCES=${SEQUENCES:-2}
FRAMES=${FRAMES:-}
TRACK_FLAGS=${TRACK_FLAGS:-}
TOLERANCE_MM=${TOLERANCE_MM:-2}
TOLERANCE_DEG=${TOLERANCE_DEG:-1}
[ -x "$ARPOS" ] || { echo "measure_tracking: no $ARPOS (build the arpos target or set ARPOS)" >&2; exit 2; }
if [ $# -eq 0 ]; then
  set -- xtion:41-43 l515:44 "xtion:45:--hard" "xtion:46-50:--random-conditions" "xtion:41-43:--room-texture plain"
fi
mkdir -p "$WORK"
RESULTS=$WORK/results.tsv
printf 'condition\tseed\tsequence\tstage\tframes\tlost_pct\tmte_mm\tmre_deg\tmedian_mm\tp95_mm\tmedian_deg\tp95_deg\treported_in\treported_out\treported_lost\ttruly_in\ttruly_out\tin_while_out\tout_while_in\tshift_err_mean_mm\tshift_err_p95_mm\tturn_err_mean_deg\tturn_err_p95_deg\tmean_total_ms\n' > "$RESULTS"

# The last line of a log without progress lines, shortened.
last_message() {
  grep -v '^\[ *[0-9]*%\]' "$1" | sed '/^ *$/d' | tail -1 | cut -c1-160 | tr '\t' ' '
}
# A number from `arpos evaluate --json`: json_number FILE KEY (top level) or
# json_stat FILE KEY STAT (inside the KEY object); nan when absent or null.
json_number() {
  v=$(sed -n "s/^ *\"$2\": *\([0-9.e+-]*\),*$/\1/p" "$1" | head -1)
  echo "${v:-nan}"
}
json_stat() {
  v=$(sed -n "s/.*\"$2\": *{[^}]*\"$3\": *\([0-9.e+-]*\).*/\1/p" "$1" | head -1)
  echo "${v:-nan}"
}
# The mean of the total_ms column of timing.csv.
mean_total_ms() {
  awk -F, 'NR == 1 { for (i = 1; i <= NF; ++i) if ($i == "total_ms") c = i; next }
           c && $c != "" { s += $c; n++ } END { if (n) printf "%.1f", s / n; else print "nan" }' "$1"
}
# One TSV row for a seed that stopped at STAGE: fail COND SEED STAGE LOG.
fail() {
  echo "$1 seed $2: FAILED $3: $(last_message "$4")"
  printf '%s\t%s\t-\t%s' "$1" "$2" "$3" >> "$RESULTS"
  for _ in $(seq 1 20); do printf '\tnan' >> "$RESULTS"; done
  printf '\n' >> "$RESULTS"
}

for spec in "$@"; do
  profile=${spec%%:*}
  rest=${spec#*:}
  seeds=${rest%%:*}
  flags=""
  case "$rest" in *:*) flags=${rest#*:} ;; esac
  case "$seeds" in
    *-*) first=${seeds%-*}; last=${seeds#*-} ;;
    *) first=$seeds; last=$seeds ;;
  esac
  cond=$(printf '%s %s' "$profile" "$flags" | sed 's/ *$//')
  tag=$(printf '%s' "$flags" | tr -c 'A-Za-z0-9.=' '_' | sed 's/__*/_/g; s/^_//; s/_$//')
  for s in $(seq "$first" "$last"); do
    C=$WORK/${profile}${tag:+_$tag}_s$s
    want="$profile $s $flags ${FRAMES:+--frames $FRAMES} --tracking-sequences $SEQUENCES"
    if [ ! -f "$C/simulation.yaml" ] || [ "$(cat "$C.flags" 2>/dev/null)" != "$want" ]; then
      rm -rf "$C" "$C.flags"
      # shellcheck disable=SC2086
      if ! "$ARPOS" simulate "$C" --profile "$profile" --seed "$s" $flags ${FRAMES:+--frames "$FRAMES"} \
          --tracking-sequences "$SEQUENCES" > "$C.simulate.txt" 2>&1; then
        fail "$cond" "$s" simulate "$C.simulate.txt"
        continue
      fi
      echo "$want" > "$C.flags"
    fi
    rm -rf "$C.db" "$C.out"
    mkdir -p "$C.out"
    if ! "$ARPOS" plan "$C" --store "$C.db" > "$C.plan.txt" 2>&1; then
      fail "$cond" "$s" plan "$C.plan.txt"
      continue
    fi
    if ! "$ARPOS" session "$C" --store "$C.db" > "$C.session.txt" 2>&1; then
      fail "$cond" "$s" session "$C.session.txt"
      continue
    fi
    for SEQ in "$C"/tracking/seq_*; do
      [ -d "$SEQ" ] || continue
      name=$(basename "$SEQ")
      OUT=$C.out/$name
      # shellcheck disable=SC2086
      if ! "$ARPOS" track "$SEQ" --store "$C.db" --out "$OUT" --tolerance-mm "$TOLERANCE_MM" \
          --tolerance-deg "$TOLERANCE_DEG" $TRACK_FLAGS > "$OUT.track.txt" 2>&1; then
        fail "$cond" "$s" "track $name" "$OUT.track.txt"
        continue
      fi
      # Exit status 1 (nothing matched: every frame lost) still writes the
      # counts; the figures are then nan.
      "$ARPOS" evaluate --gt "$SEQ/body_groundtruth.txt" --est "$OUT/poses.txt" --json \
        > "$OUT.poses.json" 2> "$OUT.poses.err" || true
      "$ARPOS" evaluate --corrections "$OUT/corrections.csv" --gt "$SEQ/body_groundtruth.txt" \
        --target "$C/target_pose.txt" --tolerance-mm "$TOLERANCE_MM" --tolerance-deg "$TOLERANCE_DEG" --json \
        > "$OUT.corrections.json" 2> "$OUT.corrections.err" || true
      P=$OUT.poses.json
      K=$OUT.corrections.json
      if [ ! -s "$P" ] || [ ! -s "$K" ]; then
        fail "$cond" "$s" "evaluate $name" "$([ -s "$P" ] && echo "$OUT.corrections.err" || echo "$OUT.poses.err")"
        continue
      fi
      row=$(printf '%s\t' "$cond" "$s" "$name" ok \
        "$(json_number "$P" ground_truth_frames)" "$(json_number "$P" lost_percent)" \
        "$(json_stat "$P" translation_mm mean)" "$(json_stat "$P" rotation_deg mean)" \
        "$(json_stat "$P" translation_mm median)" "$(json_stat "$P" translation_mm p95)" \
        "$(json_stat "$P" rotation_deg median)" "$(json_stat "$P" rotation_deg p95)" \
        "$(json_number "$K" reported_in)" "$(json_number "$K" reported_out)" "$(json_number "$K" reported_lost)" \
        "$(json_number "$K" truly_in)" "$(json_number "$K" truly_out)" \
        "$(json_number "$K" in_while_out)" "$(json_number "$K" out_while_in)" \
        "$(json_stat "$K" translation_mm mean)" "$(json_stat "$K" translation_mm p95)" \
        "$(json_stat "$K" rotation_deg mean)" "$(json_stat "$K" rotation_deg p95)")
      row="$row$(mean_total_ms "$OUT/timing.csv")"
      printf '%s\n' "$row" >> "$RESULTS"
      printf '%s\n' "$row" | awk -F '\t' '{
        printf "%s seed %s %s: %s frames, lost %.1f %%, MTE %.2f mm (median %.2f, p95 %.2f), MRE %.3f deg (p95 %.3f); " \
               "reported in %d out %d lost %d, truly in %d out %d, IN WHILE OUT %d, out while in %d; " \
               "shift error mean %.2f mm p95 %.2f; %.0f ms/frame\n",
               $1, $2, $3, $5, $6, $7, $9, $10, $8, $12, $13, $14, $15, $16, $17, $18, $19, $20, $21, $24 }'
    done
  done
done

# Summary per condition, then over everything. A seed counts as failed once
# (its first failing stage); sequences are the ones evaluated.
awk -F '\t' '
  function add(key) {
    if (!(key in seen_key)) { seen_key[key] = 1; order[++keys] = key }
    if (!((key, $2) in seeds)) { seeds[key, $2] = 1; nseeds[key]++ }
    if ($4 != "ok") {
      if (!((key, $2) in failed)) { failed[key, $2] = 1; nfailed[key]++; why[key] = why[key] sep1[key] "seed " $2 " " $4; sep1[key] = ", " }
      return
    }
    n[key]++
    for (c = 6; c <= 24; ++c) {
      if ($c == "nan") continue
      cnt[key, c]++; sum[key, c] += $c
      if (!((key, c) in mx) || $c > mx[key, c]) mx[key, c] = $c
    }
    unsafe[key] += ($18 == "nan" ? 0 : $18)
    outin[key] += ($19 == "nan" ? 0 : $19)
    frames[key] += $5
  }
  function mean(key, c) { return cnt[key, c] ? sum[key, c] / cnt[key, c] : "nan" }
  function fmt(f, key, c) { return cnt[key, c] ? sprintf(f, mean(key, c)) "/" sprintf(f, mx[key, c]) : "n/a" }
  NR > 1 { add($1); add("all") }
  END {
    if (keys == 0) exit
    print ""
    print "summary (mean/max over sequences; in while out and out while in: frames, summed):"
    # The conditions in order of appearance, then all of them.
    for (i = 1; i <= keys + 1; ++i) {
      k = i <= keys ? order[i] : "all"
      if (i <= keys && k == "all") continue
      line = sprintf("%-28s %2d seeds, %d failed%s; %d sequences", k, nseeds[k], nfailed[k] + 0,
                     nfailed[k] ? " (" why[k] ")" : "", n[k] + 0)
      if (n[k] > 0) {
        line = line sprintf(": lost %s %%, MTE %s mm, p95 %s mm, MRE %s deg; in while out %d of %d frames, out while in %d; shift error %s mm; %s ms/frame",
                            fmt("%.1f", k, 6), fmt("%.2f", k, 7), fmt("%.2f", k, 10), fmt("%.3f", k, 8),
                            unsafe[k], frames[k], outin[k], fmt("%.2f", k, 20), fmt("%.0f", k, 24))
      }
      print line
    }
    bad = nfailed["all"] + unsafe["all"]
    exit (bad > 0)
  }' "$RESULTS"
