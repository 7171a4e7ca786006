#!/bin/bash
# cmp.sh OUTDIR BENCH PAIRS SEED ROUNDS binA binB ...
out=$1; bench=$2; pairs=$3; seed=$4; rounds=$5; shift 5
B=/work/shared/data/3dmatch/benchmarks
mkdir -p $out
for r in $(seq 1 $rounds); do
  for bin in "$@"; do
    name=$(basename $bin)
    rm -f $out/$name-$r.jsonl
    /usr/bin/time -f "%e s" $bin eval $B/$bench --pairs $pairs --seed $seed --threads 2 --records $out/$name-$r.jsonl > $out/$name-$r.out 2> $out/$name-$r.err
    echo "$name round $r: $(tail -1 $out/$name-$r.err)"
  done
done
