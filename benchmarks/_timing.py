"""Timing helpers shared by the benchmark scripts (imported as a sibling module)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any


class Timed:
    """Wraps a callable and adds up its wall time and calls."""

    def __init__(self, fn: Callable[..., Any]) -> None:
        self.fn = fn
        self.seconds = 0.0
        self.calls = 0

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        try:
            return self.fn(*args, **kwargs)
        finally:
            self.seconds += time.perf_counter() - start
            self.calls += 1


def timed_acts(env: Any, agent: Any, obs: Any, max_frames: int,
               on_observation: Callable[[Any], None] | None = None) -> tuple[float, int, Any]:
    """Step ``env`` with ``agent`` from ``obs`` for up to ``max_frames`` frames.

    Only ``agent.act`` is timed (the env's decode and scoring are not).

    Returns:
        ``(seconds in act, frames played, the last observation)``.
    """
    seconds, frames = 0.0, 0
    while frames < max_frames:
        if on_observation is not None:
            on_observation(obs)
        start = time.perf_counter()
        action = agent.act(obs)
        seconds += time.perf_counter() - start
        frames += 1
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    return seconds, frames, obs


#: Peak resident memory of the running process, as a Python snippet. ``ru_maxrss`` is kept
#: across ``execve`` on Linux, so a child started by a large benchmark process would report the
#: parent's peak; ``VmHWM`` in /proc/self/status belongs to the child's own address space.
PEAK_RSS_GIB = (
    "def peak_rss_gib():\n"
    "    try:\n"
    "        for line in open('/proc/self/status'):\n"
    "            if line.startswith('VmHWM:'):\n"
    "                return int(line.split()[1]) / 2**20\n"
    "    except OSError:\n"
    "        pass\n"
    "    import resource\n"
    "    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20\n"
)
