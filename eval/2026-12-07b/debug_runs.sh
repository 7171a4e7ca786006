#!/bin/bash
# Fifteen room runs (five rooms, seeds 0-2), two at a time, one thread each, with the
# debug prints of room-switches.patch: bash debug_runs.sh MTPCR ROOMS_DIR OUT [VAR=value ...]
mtpcr=$1; rooms=$2; out=$3; shift 3; mkdir -p "$out"
i=0
for s in 0 1 2; do for room in "$rooms"/*.json; do
  n=$(basename "$room" .json | cut -c1-12)
  env MTPCR_DEBUG_ROOM=1 "$@" "$mtpcr" eval "$room" --runs 1 --seed $s --threads 1 \
    --json "$out/s$s-$n.json" > "$out/s$s-$n.out" 2> "$out/s$s-$n.err" &
  i=$((i+1)); if (( i % 2 == 0 )); then wait; fi
done; done
wait
