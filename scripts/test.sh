#!/usr/bin/env bash
# Runs every check and test of mtpcr: formatting, lints, Rust unit/integration/doc tests
# (release mode: the registration tests are too slow in debug), then the Python package
# built and installed into a fresh venv with its pytest suite.
# Real-data tests use ../shared (or $MTPCR_SHARED_DIR) and skip with a reason when absent.
set -euo pipefail
cd "$(dirname "$0")/.."

echo "== cargo fmt --check"
cargo fmt --all -- --check
echo "== cargo clippy"
cargo clippy --workspace --all-targets --release -- -D warnings
echo "== cargo test"
cargo test --workspace --release
echo "== python tests"
bash scripts/python-tests.sh
