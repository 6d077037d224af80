#!/usr/bin/env bash
# Create a virtual environment (./.venv, or $UNITRACK_VENV) and install unitrack-env into it,
# in the order that avoids two traps:
#  1. torch: install the CPU build first (a bare `torch` requirement would pull a multi-GB
#     CUDA build). Override with TORCH_SPEC, e.g. TORCH_SPEC="torch==2.13.0" (default).
#  2. TrackEval: every release's metadata requires `opencv-python` (the GUI build, needs
#     libGL), which would overwrite opencv-python-headless's cv2. Its real needs are our own
#     dependencies, so it is installed last with --no-deps. pip would then call that missing
#     opencv-python a red "ERROR" on every later install, so installs skip pip's conflict
#     warning and `pip check` runs at the end instead, saying every conflict but its known ones.
# Usage: bash scripts/setup.sh          # runtime only (editable install of this checkout)
#        bash scripts/setup.sh test     # + test tools (pytest, ruff, scikit-image, video)
#        UNITRACK_WHEEL=dist/unitrack_env-0.1.0-py3-none-any.whl bash scripts/setup.sh
#                                       # install a built wheel instead of the checkout
set -euo pipefail
cd "$(dirname "$0")/.."
extras="${1:-}"
venv="${UNITRACK_VENV:-.venv}"
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
python="$(cd "$venv" && pwd)/bin/python"
pip=("$python" -m pip install --quiet --disable-pip-version-check)
"${pip[@]}" "${TORCH_SPEC:-torch==2.13.0}"
target=(-e .)
[ -n "${UNITRACK_WHEEL:-}" ] && target=("$UNITRACK_WHEEL")
if [ -n "$extras" ]; then
    target[-1]="${target[-1]}[$extras]"
fi
"${pip[@]}" --no-warn-conflicts "${target[@]}"
"${pip[@]}" --no-deps "trackeval==1.3.0"
# trackeval also declares matplotlib, used only for its plots (off here; the `plots` extra)
known="^trackeval [0-9.]* requires (opencv-python|matplotlib)[^,]*, which is not installed"
conflicts="$("$python" -m pip check 2>&1 | grep -v -E -e "$known" -e "^No broken requirements" || true)"
[ -z "$conflicts" ] || printf 'pip check found these conflicts:\n%s\n' "$conflicts" >&2
(cd / && "$python" -c "import unitrack_env.agents, unitrack_env.evaluation, trackeval, torch; print('unitrack-env ready:', unitrack_env.__version__, '| torch', torch.__version__)")
