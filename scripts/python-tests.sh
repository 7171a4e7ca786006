#!/usr/bin/env bash
# Builds and installs the Python package into a fresh venv (target/py-venv) the way a user
# would (`pip install .`: pip fetches maturin as the build backend and numpy as a dependency),
# then runs the pytest suite. Extra arguments go to pytest. Needs only Rust, Python 3.9+ and
# network access to PyPI (or a pip cache). Real-data tests use ../shared (or
# $MTPCR_SHARED_DIR) and skip with a reason when it is absent.
set -euo pipefail
cd "$(dirname "$0")/.."
# Ray (tests of mtpcr.distributed) sends no usage statistics.
export RAY_USAGE_STATS_ENABLED=0

PYTHON="${PYTHON:-python3}"
VENV=target/py-venv
export PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_NO_INPUT=1 PIP_PROGRESS_BAR=off

echo "== fresh venv in $VENV ($("$PYTHON" --version))"
"$PYTHON" -m venv --clear "$VENV"
echo "== pip install . pytest ruff ray"
start=$(date +%s)
# ray: for the tests of mtpcr.distributed (python/tests/test_distributed.py, marker `ray`).
"$VENV/bin/python" -m pip install . pytest ruff ray
echo "   installed in $(( $(date +%s) - start )) s"
echo "== ruff"
"$VENV/bin/python" -m ruff check python
"$VENV/bin/python" -m ruff format --check python
echo "== pytest python/tests"
# Run from outside the source tree's package folder so the installed package is tested.
"$VENV/bin/python" -m pytest python/tests -q "$@"
