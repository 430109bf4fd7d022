#!/usr/bin/env bash
# Runs lucerna's whole test suite: the Rust tests (release build, so rendering tests are fast),
# the Python tests, which read the renderer's EXR output with OpenImageIO and use the pip
# package built from python/, and the USD plugin's tests (plugins/usd/tests, usd-core).
# Python packages go into a virtual environment (.venv, or $LUCERNA_VENV) made on first use.
set -euo pipefail
cd "$(dirname "$0")/.."

venv="${LUCERNA_VENV:-.venv}"
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r tests/requirements.txt

cargo build --release --locked
# The pip package (python/: the library for Python, its command line, the plugin), built into
# a wheel and installed into the venv, as `pip install` of a release would.
"$venv/bin/maturin" build --quiet --release --locked -m python/Cargo.toml --out target/wheels
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps --force-reinstall \
    target/wheels/lucerna-*.whl
if cargo nextest --version >/dev/null 2>&1; then
    cargo nextest run --release --locked --no-fail-fast
else
    cargo test --release --locked --no-fail-fast
fi
LUCERNA_BIN="$PWD/target/release/lucerna" LUCERNA_PYTHON="$(cd "$venv" && pwd)/bin/python" \
    "$venv/bin/python" -m pytest -q tests/python plugins/usd/tests
