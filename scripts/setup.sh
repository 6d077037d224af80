#!/usr/bin/env bash
# Create ./.venv and install unitrack-env into it, in the order that avoids two traps:
#  1. torch: install the CPU build first (a bare `torch` requirement would pull a multi-GB
#     CUDA build). Override with TORCH_SPEC, e.g. TORCH_SPEC="torch==2.13.0" (default).
#  2. TrackEval: its metadata requires `opencv-python` (the GUI build, needs libGL), which
#     would overwrite opencv-python-headless's cv2. Its real needs are our own dependencies,
#     so it is installed last with --no-deps.
# Usage: bash scripts/setup.sh          # runtime only
#        bash scripts/setup.sh test     # + test tools (pytest, ruff, scikit-image)
set -euo pipefail
cd "$(dirname "$0")/.."
extras="${1:-}"
venv="${UNITRACK_VENV:-.venv}"
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
pip=("$venv/bin/python" -m pip install --quiet --disable-pip-version-check)
"${pip[@]}" "${TORCH_SPEC:-torch==2.13.0}"
if [ -n "$extras" ]; then
    "${pip[@]}" -e ".[$extras]"
else
    "${pip[@]}" -e .
fi
"${pip[@]}" --no-deps "trackeval==1.3.0"
"$venv/bin/python" -c "import unitrack_env.agents, unitrack_env.evaluation, trackeval, torch; print('unitrack-env ready:', unitrack_env.__version__, '| torch', torch.__version__)"
