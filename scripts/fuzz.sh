#!/usr/bin/env bash
# Fuzzes mtpcr-core: the file readers and the register entry point. Runs each target (or the
# ones named) for SECONDS.
#   scripts/fuzz.sh SECONDS [read_ply_bytes] [read_scans_bytes] [register]
# Needs a nightly toolchain and cargo-fuzz (`rustup toolchain install nightly`,
# `cargo install cargo-fuzz`). The readers' seeds are valid files of every format, generated
# by the core's corpus test; their crashes land in fuzz/artifacts/TARGET/ (add each to the
# regression corpus in crates/mtpcr-core/src/io/corpus.rs once fixed). `register` needs no
# seeds (any bytes decode to clouds and a config); its crashes become tests in
# crates/mtpcr-core/tests/fuzz_register.rs (MTPCR_FUZZ_PRINT=1 prints an input's clouds).
# Builds optimised, as users build; set FUZZ_DEBUG_ASSERTIONS=1 to turn debug assertions and
# overflow checks on (laz 0.13 then stops at its own debug_assert! on corrupt LAZ data, which
# release builds do not have).
set -euo pipefail
seconds=${1:?usage: scripts/fuzz.sh SECONDS [TARGET...]}
shift
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(read_ply_bytes read_scans_bytes register)
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

if ! cargo +nightly --version >/dev/null 2>&1; then
    echo "fuzz.sh: no nightly toolchain (rustup toolchain install nightly)" >&2; exit 2
fi
if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "fuzz.sh: cargo-fuzz is not installed (cargo install cargo-fuzz)" >&2; exit 2
fi

# Seeds: the corpus test writes the valid files it checks into this folder.
seeds=fuzz/corpus/seeds
mkdir -p "$seeds"
MTPCR_FUZZ_SEEDS="$root/$seeds" cargo test -q -p mtpcr-core --release --lib \
    io::corpus::seeds_read_back_with_their_points >/dev/null
mkdir -p fuzz/corpus/read_ply_bytes fuzz/corpus/read_scans_bytes fuzz/corpus/register
cp "$seeds"/*.ply fuzz/corpus/read_ply_bytes/
# read_scans_bytes: the first byte picks the file name's extension (see its source).
exts=(xyz pts csv txt ply pcd e57 las laz)
for f in "$seeds"/*; do
    ext=${f##*.}
    for i in "${!exts[@]}"; do
        if [ "${exts[$i]}" = "$ext" ]; then
            { printf "\\x$(printf %02x "$i")"; cat "$f"; } > "fuzz/corpus/read_scans_bytes/$(basename "$f")"
        fi
    done
done

flags=(-O)
[ "${FUZZ_DEBUG_ASSERTIONS:-0}" = 1 ] && flags+=(-a)
# FUZZ_KEEP_GOING=1: fork mode, recording crashes in fuzz/artifacts/ and going on after them
# (for a known crash that cannot be fixed here, see the report in crates/mtpcr-core/src/io/las.rs).
extra=()
[ "${FUZZ_KEEP_GOING:-0}" = 1 ] && extra+=(-fork=1 -ignore_crashes=1 -ignore_ooms=1 -ignore_timeouts=1)
cd fuzz
for target in "${targets[@]}"; do
    echo "== $target for ${seconds}s"
    cargo +nightly fuzz run "${flags[@]}" "$target" "corpus/$target" -- \
        -max_total_time="$seconds" -max_len=65536 -timeout=20 -rss_limit_mb=4096 -print_final_stats=1 "${extra[@]}"
done
