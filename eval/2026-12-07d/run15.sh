#!/bin/bash
# bash run15.sh BIN OUT [VAR=value ...]: five rooms x seeds 0-2, two at a time, one thread each
bin=$1; out=$2; shift 2; mkdir -p "$out"
i=0
for s in 0 1 2; do for room in ${ROOMS:-/tmp/rooms}/*.json; do
  n=$(basename "$room" .json | cut -c1-12)
  env "$@" "$bin" eval "$room" --runs 1 --seed $s --threads 1 --json "$out/s$s-$n.json" > "$out/s$s-$n.out" 2> "$out/s$s-$n.err" &
  i=$((i+1)); if (( i % 2 == 0 )); then wait; fi
done; done
wait; echo ALL-DONE
