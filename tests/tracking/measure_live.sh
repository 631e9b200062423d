#!/bin/sh
# Live tracking as a clinic would run it, measured: the simulator as a live
# camera (sim:CASE?frames=F, delivered at 30 fps), tracked with the recorder
# on (--record) and OpenIGTLink's example client connected (--igtl-port,
# --igtl-wait), one line a case:
#   frames captured / tracked / dropped by tracking, lost %, ms per frame,
#   recorder written / dropped, stream latency (correction to wire), and
#   MTE / MRE of poses.txt against the truth the simulated camera gave (the
#   recording's body_groundtruth.txt; a dropped frame counts as lost there).
#   tests/tracking/measure_live.sh CASE:STORE [CASE:STORE ...]
# CASE is a simulated case (arpos simulate) whose STORE has an open session
# on it (arpos run-case CASE --store STORE --keep-open, or plan + session);
# the store is copied, never changed. Environment: BUILD (default build),
# WORK (default /tmp/arpos_live), FRAMES (default 300), TRACK_FLAGS (extra
# options for arpos track, e.g. --sequential), PORT (default 18950).
set -eu
BUILD=${BUILD:-build}
ARPOS=$BUILD/bin/arpos
CLIENT=$BUILD/bin/igtl_receive_client
WORK=${WORK:-/tmp/arpos_live}
FRAMES=${FRAMES:-300}
TRACK_FLAGS=${TRACK_FLAGS:-}
PORT=${PORT:-18950}
[ -x "$ARPOS" ] && [ -x "$CLIENT" ] || { echo "measure_live: build arpos and igtl_receive_client first" >&2; exit 2; }
[ $# -gt 0 ] || { sed -n '2,14p' "$0" >&2; exit 2; }
mkdir -p "$WORK"
printf 'case\tcaptured\ttracked\tdropped\tlost_pct\tms_mean\tms_p95\trec_written\trec_dropped\tigtl_mean_ms\tigtl_max_ms\tmte_mm\tmre_deg\tlost_or_dropped_pct\n'
i=0
for spec in "$@"; do
  case_dir=${spec%%:*}
  store=${spec#*:}
  name=$(basename "$case_dir")
  run="$WORK/$name"
  rm -rf "$run"
  mkdir -p "$run"
  cp "$store" "$run/store.db"
  port=$((PORT + i))
  i=$((i + 1))
  # shellcheck disable=SC2086
  "$ARPOS" track --source "sim:$case_dir?frames=$FRAMES" --case "$case_dir" --store "$run/store.db" \
    --out "$run/out" --record "$run/case/tracking/live" --igtl-port "$port" --igtl-wait $TRACK_FLAGS \
    > "$run/track.out" 2> "$run/track.err" &
  track=$!
  n=0
  until grep -q "OpenIGTLink: listening" "$run/track.err" 2>/dev/null || [ $n -ge 600 ]; do sleep 0.1; n=$((n + 1)); done
  "$CLIENT" 127.0.0.1 "$port" > "$run/client.txt" 2>&1 &
  client=$!
  status=0
  wait $track || status=$?
  sleep 0.3
  kill $client 2>/dev/null || true
  wait $client 2>/dev/null || true
  if [ $status -ne 0 ]; then
    printf '%s\tFAILED (exit %s): %s\n' "$name" "$status" "$(tail -1 "$run/track.err")"
    continue
  fi
  live=$(grep "^live:" "$run/track.err")
  summary=$(grep "^tracking " "$run/track.out")
  rec=$(grep "^recorded " "$run/track.err")
  igtl=$(grep "^OpenIGTLink: [0-9]" "$run/track.err")
  captured=$(echo "$live" | sed -n 's/live: \([0-9]*\) frames captured.*/\1/p')
  tracked=$(echo "$live" | sed -n 's/.*captured, \([0-9]*\) tracked.*/\1/p')
  dropped=$(echo "$live" | sed -n 's/.*tracked, \([0-9]*\) dropped.*/\1/p')
  lost=$(echo "$summary" | sed -n 's/.* lost (\([0-9.]*\) %.*/\1/p')
  ms=$(echo "$summary" | sed -n 's/.*; \([0-9.]*\) ms per frame (p95 \([0-9.]*\),.*/\1\t\2/p')
  rec_written=$(echo "$rec" | sed -n 's/.*: \([0-9]*\) frames written.*/\1/p')
  rec_dropped=$(echo "$rec" | sed -n 's/.*; \([0-9]*\) dropped (writer behind).*/\1/p')
  igtl_ms=$(echo "$igtl" | sed -n 's/.*wire \([0-9.]*\) ms mean, p95 [0-9.]*, max \([0-9.]*\).*/\1\t\2/p')
  "$ARPOS" evaluate --gt "$run/case/tracking/live/body_groundtruth.txt" --est "$run/out/poses.txt" \
    > "$run/evaluate.txt" 2>&1 || true
  mte=$(sed -n 's/.*mean (MTE) \([0-9.]*\).*/\1/p' "$run/evaluate.txt")
  mre=$(sed -n 's/.*mean (MRE) \([0-9.]*\).*/\1/p' "$run/evaluate.txt")
  gone=$(sed -n 's/.*lost: [0-9]* (\([0-9.]*\) %).*/\1/p' "$run/evaluate.txt")
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$name" "$captured" "$tracked" "$dropped" "$lost" "$ms" \
    "$rec_written" "$rec_dropped" "$igtl_ms" "${mte:-n/a}" "${mre:-n/a}" "${gone:-n/a}"
done
