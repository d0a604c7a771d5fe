#!/usr/bin/env bash
# Creates .venv (if needed) and installs tlshield from this checkout, with the training and test
# extras, building the Rust extension in release mode. Safe to re-run: cargo rebuilds only what
# changed and pip skips what is already installed.
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON="${PYTHON:-python3}"
VENV="${VENV:-.venv}"
EXTRAS="${EXTRAS:-train,test}"

if ! command -v cargo >/dev/null 2>&1; then
    echo "error: cargo (the Rust toolchain) is needed to build tlshield's extension; install it from rustup" >&2
    exit 1
fi
if [ ! -x "$VENV/bin/python" ]; then
    echo "==> creating $VENV"
    "$PYTHON" -m venv "$VENV"
fi
echo "==> installing tlshield[$EXTRAS] into $VENV (builds the Rust extension)"
"$VENV/bin/python" -m pip install --quiet --upgrade pip
"$VENV/bin/python" -m pip install --quiet --editable ".[$EXTRAS]"
# qpth (a baseline of benches/compare_grad.py) pins numpy<2 in its metadata although it runs on
# numpy 2; installed without dependencies (torch and numpy come with the train extra) so that
# it does not downgrade numpy.
if [[ ",$EXTRAS," == *",bench,"* ]]; then
    "$VENV/bin/python" -m pip install --quiet --no-deps "qpth==0.0.18"
fi
