#!/usr/bin/env bash
# Installs the Safety-Gymnasium stack that tlshield's adapter (tlshield.envs.safety_gym) patches,
# into the venv that scripts/setup.sh made. safety-gymnasium 1.0.0 pins gymnasium 0.28.1 and
# mujoco 2.3.3 (and a pygame without a wheel for Python 3.11), so it goes in without its
# dependencies; mujoco 2.3.7 has 2.3.3's dynamics and wheels for this Python. gymnasium 1.x and
# numpy 2 stay as tlshield needs them. docs/guides/safety-gym.md says what the adapter patches.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV="${VENV:-.venv}"
echo "==> installing safety-gymnasium 1.0.0 and mujoco 2.3.7 into $VENV"
"$VENV/bin/python" -m pip install --quiet --no-deps "safety-gymnasium==1.0.0"
"$VENV/bin/python" -m pip install --quiet "mujoco==2.3.7" xmltodict pyyaml imageio
echo "==> (pip's notes about safety-gymnasium's pins above are expected: tlshield's adapter runs it on gymnasium 1.x and mujoco 2.3.7)"
