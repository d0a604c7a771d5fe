#!/usr/bin/env bash
# The wheel as a user gets it (issue 25): build the manylinux wheel (make wheel's command, its
# own cargo target dir so the cache is reused and never fights cargo test's), check its tag
# with auditwheel, then
#   1. a fresh venv with no cargo on PATH: pip installs the wheel (numpy and gymnasium come
#      from the registry), runs the README's example and `tlshield --help`;
#   2. a second fresh venv: the wheel with its `train` extra, the training stack taken from
#      .venv (a .pth: the 2 GB torch download would dwarf the check), trains one PPO update.
# Run by `make test` after .venv is set up (it has maturin, ziglang and auditwheel).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT="$PWD"
VENV="$(cd "${VENV:-.venv}" && pwd)"

echo "==> building the wheel"
CARGO_TARGET_DIR="$ROOT/target/wheel" PATH="$VENV/bin:$PATH" \
    "$VENV/bin/maturin" build --release --zig --compatibility manylinux2014 --out dist --quiet
WHEEL="$(ls -t dist/tlshield-*manylinux*.whl | head -1)"
SHOW="$("$VENV/bin/auditwheel" show "$WHEEL")"
echo "$SHOW"
case "$(echo "$SHOW" | tr -d '\n')" in
    *'consistent with the following platform tag:"manylinux_2_17_x86_64"'*) ;;
    *) echo "error: auditwheel does not call $WHEEL manylinux_2_17" >&2; exit 1 ;;
esac

CHECK="$(mktemp -d)"
trap 'rm -rf "$CHECK"' EXIT
BASE_PYTHON="$("$VENV/bin/python" -c 'import sys; print(sys._base_executable)')"
# Only the system's directories: no ~/.cargo/bin, no rustup.
NO_RUST_PATH="$CHECK/venv/bin:/usr/local/bin:/usr/bin:/bin"

echo "==> 1. $WHEEL in a fresh venv without Rust"
"$BASE_PYTHON" -m venv "$CHECK/venv"
"$VENV/bin/python" - "$CHECK/example.py" <<'PY'
import pathlib, sys
readme = pathlib.Path("README.md").read_text()
example = readme.split("\n## Example", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
pathlib.Path(sys.argv[1]).write_text(example)
PY
env -i HOME="$CHECK" PATH="$NO_RUST_PATH" bash -c '
    set -euo pipefail
    if command -v cargo >/dev/null || command -v rustc >/dev/null; then
        echo "error: Rust is on PATH" >&2; exit 1
    fi
    pip install --quiet --disable-pip-version-check "'"$ROOT/$WHEEL"'"
    cd "'"$CHECK"'"
    python example.py
    python -c "import sys, tlshield; assert sys.prefix in tlshield.__file__, tlshield.__file__"
    tlshield --help >/dev/null
    python -c "import tlshield, sys; print(\"tlshield\", tlshield.__version__, \"from\", tlshield.__file__)"
'

echo "==> 2. $WHEEL[train] in a fresh venv: one PPO update"
"$BASE_PYTHON" -m venv "$CHECK/train"
SITE="$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
TRAIN_SITE="$("$CHECK/train/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
echo "$SITE" > "$TRAIN_SITE/training-stack.pth"
env -i HOME="$CHECK" PATH="$CHECK/train/bin:/usr/local/bin:/usr/bin:/bin" bash -c '
    set -euo pipefail
    pip install --quiet --disable-pip-version-check --force-reinstall --no-deps "'"$ROOT/$WHEEL"'"
    pip install --quiet --disable-pip-version-check "'"$ROOT/$WHEEL"'[train]"
    cd "'"$CHECK"'"
    python -c "import sys, tlshield; assert sys.prefix in tlshield.__file__, tlshield.__file__"
    tlshield train --config rl_cbf_clf --updates 1 --seed 0 --out run --quiet
    test -f run/run.json && test -f run/metrics.csv
    echo "one update trained: $(wc -l < run/metrics.csv) lines of metrics"
'
echo "==> the wheel works as a user gets it"
