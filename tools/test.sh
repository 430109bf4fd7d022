#!/usr/bin/env bash
# Runs lucerna's whole test suite: the Rust tests (release build, so rendering tests are fast),
# the Python tests, which read the renderer's EXR output with OpenImageIO and use the pip
# package built from python/, and the USD plugin's tests (plugins/usd/tests, usd-core).
# Python packages go into a virtual environment (.venv, or $LUCERNA_VENV) made on first use.
#
# On a fresh clone of a 2-core machine it takes about 7 minutes, most of it compiling; each
# step says what it does and how long it took.
set -euo pipefail
cd "$(dirname "$0")/.."

start=$SECONDS
step_start=$SECONDS
step_name=""
# Prints how long the step before took, then the next step's name.
step() {
    if [ -n "$step_name" ]; then
        echo "== ${step_name%%:*}: $((SECONDS - step_start)) s" >&2
    fi
    step_name="$1"
    step_start=$SECONDS
    echo "== [$(date +%H:%M:%S)] $1" >&2
}

venv="${LUCERNA_VENV:-.venv}"
step "1/5 Python environment ($venv): test requirements (about 30 s the first time)"
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r tests/requirements.txt

step "2/5 cargo build --release (about 3 minutes from scratch on 2 cores)"
cargo build --release --locked

# The pip package (python/: the library for Python, its command line, the plugin), built into
# a wheel and installed into the venv, as `pip install` of a release would.
step "3/5 the Python package's wheel (maturin; about 2 minutes from scratch)"
"$venv/bin/maturin" build --quiet --release --locked -m python/Cargo.toml --out target/wheels
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps --force-reinstall \
    target/wheels/lucerna_render-*.whl

step "4/5 Rust tests (unit tests and tests/it; about 2 minutes)"
if cargo nextest --version >/dev/null 2>&1; then
    cargo nextest run --release --locked --no-fail-fast
else
    cargo test --release --locked --no-fail-fast
fi

step "5/5 Python tests (tests/python, plugins/usd/tests; about 1 minute)"
LUCERNA_BIN="$PWD/target/release/lucerna" LUCERNA_PYTHON="$(cd "$venv" && pwd)/bin/python" \
    "$venv/bin/python" -m pytest -q tests/python plugins/usd/tests

step "done"
echo "== all tests passed in $((SECONDS - start)) s" >&2
