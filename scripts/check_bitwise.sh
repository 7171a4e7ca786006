#!/usr/bin/env bash
# Checks that the engine still gives the transforms recorded in eval/bitwise/before-*.json
# (captured before the view-graph reshaping of the core): the six shared problems, seeds 0-9,
# with the paper setting, MFEA, G-MFEA and the earlier default setting. Needs ../shared and a
# release build; takes about 10 minutes on 2 cores (the default variant 6 of them).
# Known, intended differences since: the stray-point removal of the samples (2026-12-01) drops
# one sample point of dragonStandRight_288.ply in every setting, so the 10 dragon-c runs of
# each variant differ (paper, 2026-12-02: the other 50 of 60 runs still bit-identical).
# Since 2026-12-02's second session every run differs: the aiding loss's distance field has
# nodes 3 eps apart (were 2) and the joint ICP ends at a trim set by the point spacing, so
# these files now only document the reshaping. To check a refactoring today, record the
# reports first (`mtpcr eval ... --json before.json`, same flags) and compare them after with
# `python3 scripts/compare_transforms.py before.json after.json`.
# Usage: bash scripts/check_bitwise.sh [paper|mfea|gmfea|default ...]   (default: all four)
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q -p mtpcr-cli
out=$(mktemp -d)
status=0
for variant in "${@:-paper mfea gmfea default}"; do
  for v in $variant; do
    case $v in
      paper) flags=(--paper) ;;
      mfea) flags=(--paper --method mfea) ;;
      gmfea) flags=(--paper --method gmfea) ;;
      # The default setting before feature hypotheses and early stopping existed.
      default) flags=(--order given --hypotheses 0 --stop-when-restarts-agree false --max-sample-points 0 --population-size 100 --generations 30) ;;
      *) echo "unknown variant $v" >&2; exit 2 ;;
    esac
    echo "== $v"
    ./target/release/mtpcr eval ../shared/problems/*.json --runs 10 --seed 0 -q --threads 2 \
      "${flags[@]}" --json "$out/$v.json" > /dev/null
    python3 scripts/compare_transforms.py "eval/bitwise/before-$v.json" "$out/$v.json" || status=1
  done
done
rm -rf "$out"
exit $status
