#!/bin/bash
# Two builds' seconds on every room, seed 0, one thread each: both at once, pinned one to
# each core, then the other way round (one unpinned run's seconds spread by 15 % here).
# Usage: pinned_times.sh BEFORE_BINARY AFTER_BINARY ROOMS_FOLDER OUT_FOLDER
#   (ROOMS_FOLDER from `python3 scripts/make_scene_problems.py --out ROOMS_FOLDER`)
# then: python3 eval/2026-12-07/pinned_times.py OUT_FOLDER
set -eu
before=$1 after=$2 rooms=$3 out=$4
mkdir -p "$out"
for room in "$rooms"/*.json; do
  n=$(basename "$room" .json | cut -c1-12)
  for order in 0 1; do
    taskset -c $order "$before" eval "$room" --runs 1 --seed 0 --threads 1 \
      --json "$out/before-$order-$n.json" > "$out/before-$order-$n.out" 2>&1 &
    taskset -c $((1 - order)) "$after" eval "$room" --runs 1 --seed 0 --threads 1 \
      --json "$out/after-$order-$n.json" > "$out/after-$order-$n.out" 2>&1 &
    wait
  done
done
