#!/usr/bin/env bash
# Regenerates sample_sessions/demo_xtion, the small simulated case committed
# for the README's main command and the integration tests.
#   tools/make_sample_session.sh [ARPOS_BINARY]
# Deterministic: the same arpos build writes the same bytes. Larger cases:
# `arpos simulate OUT_DIR` (see `arpos simulate --help`).
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
arpos="${1:-$here/build/bin/arpos}"
out="$here/sample_sessions/demo_xtion"
rm -rf "$out"
"$arpos" simulate "$out" --profile xtion --seed 1 \
  --room-walk couch --frames room=24,body=8,tracking=3 --tracking-sequences 1 \
  --png-compression 9
"$arpos" check "$out"
du -sh "$out"
