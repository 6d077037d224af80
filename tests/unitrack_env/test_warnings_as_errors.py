"""Readers and scorers under ``-W error::DeprecationWarning``, as a user project may run.

A third-party warning inside our readers or scorers (pycocotools' numpy 2 warning) must not
become an error of the user's data. The child process gets no warning filters of ours (not
pytest's, not pyproject's): it plays every registered id's first (synthetic) sequence to
the end and scores it with the official scorer (about 20 s on the 2-core CI machine).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

_CHILD = r"""
import gymnasium as gym
import unitrack_env

for env_id in unitrack_env.env_ids():
    env = gym.make(env_id)
    base = env.unwrapped
    env.reset(options={"sequence": base.sequence_names[0]})
    env.action_space.seed(0)
    action = env.action_space.sample()
    if isinstance(action, dict):  # a few tracks keep the scoring cheap
        action = {k: min(v, 3) if k.startswith("num_") else v for k, v in action.items()}
    done = False
    while not done:
        _, _, terminated, truncated, _ = env.step(action)
        done = terminated or truncated
    assert base.episode_metrics(), env_id
    env.close()
    print("ok", env_id, flush=True)
"""


def test_every_env_resets_steps_and_scores_with_deprecation_warnings_as_errors():
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(REPO), os.environ.get("PYTHONPATH", "")]))
    env.pop("PYTHONWARNINGS", None)
    done = subprocess.run(
        [sys.executable, "-W", "error::DeprecationWarning", "-c", _CHILD],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-4000:]
    import unitrack_env

    played = {line.split()[1] for line in done.stdout.splitlines() if line.startswith("ok ")}
    assert played == set(unitrack_env.env_ids())
