#!/usr/bin/env bash
# Runs every check and test of mtpcr: formatting, lints, Rust unit/integration/doc tests
# (release mode: the registration tests are too slow in debug), then the Python package
# built and installed into a fresh venv with its pytest suite.
# Real-data tests use ../shared (or $MTPCR_SHARED_DIR) and skip with a reason when absent.
set -euo pipefail
cd "$(dirname "$0")/.."

echo "== cargo fmt --check"
cargo fmt --all -- --check
echo "== module circles in mtpcr-core"
# The shared tool (../shared/tools, or $MTPCR_SHARED_DIR/tools) exits 1 on an import circle.
cycles="${MTPCR_SHARED_DIR:-../shared}/tools/rust_module_cycles.py"
if [ -f "$cycles" ]; then
  python3 "$cycles" crates/mtpcr-core/src
else
  echo "skipped: $cycles not found"
fi
echo "== cargo clippy"
cargo clippy --workspace --all-targets --release -- -D warnings
echo "== cargo test"
cargo test --workspace --release
echo "== python tests"
bash scripts/python-tests.sh

# Outside CI, crates/mtpcr-cli/tests/viewer_browser.rs passes without checking anything when
# no Chromium is found (in CI, CI=true, it fails instead); say so where it is seen.
if [ -z "${MTPCR_CHROMIUM:-}" ] && ! command -v chromium >/dev/null 2>&1 \
  && ! command -v chromium-browser >/dev/null 2>&1; then
  echo
  echo "NOTE: the browser test of view.html was skipped: chromium not found" \
    "(apt-get install chromium; CI=true makes this a failure)"
fi
