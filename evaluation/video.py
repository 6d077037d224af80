"""Render an agent's episode to a video file (``unitrack render``)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import cv2
import gymnasium as gym

import unitrack_env
from unitrack_env.agents import make_agent

#: FourCC codes by file extension (both ship with opencv-python-headless).
_FOURCC = {".mp4": "mp4v", ".avi": "MJPG"}


def render_episode(
    env_id: str,
    agent: str,
    sequence: str,
    out: str | os.PathLike,
    *,
    env_kwargs: dict[str, Any] | None = None,
    agent_kwargs: dict[str, Any] | None = None,
    fps: float | None = None,
) -> int:
    """Play one sequence and write every rendered frame to ``out``; return the frame count."""
    out = Path(out)
    if out.suffix.lower() not in _FOURCC:
        raise ValueError(f"{out}: video extension must be one of {sorted(_FOURCC)}")
    unitrack_env.register_all()
    env = gym.make(env_id, render_mode="rgb_array", **(env_kwargs or {}))
    tracker = make_agent(agent, **(agent_kwargs or {}))
    writer = None
    frames = 0
    try:
        observation, info = env.reset(options={"sequence": sequence})
        tracker.reset(observation, info)
        rate = fps or float(info.get("frame_rate", 25.0))
        terminated = truncated = False
        while not (terminated or truncated):
            observation, _, terminated, truncated, _ = env.step(tracker.act(observation))
            image = env.render()
            if writer is None:
                out.parent.mkdir(parents=True, exist_ok=True)
                height, width = image.shape[:2]
                fourcc = cv2.VideoWriter_fourcc(*_FOURCC[out.suffix.lower()])
                writer = cv2.VideoWriter(str(out), fourcc, rate, (width, height))
                if not writer.isOpened():
                    raise OSError(f"{out}: OpenCV could not open a video writer")
            writer.write(cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
            frames += 1
    finally:
        if writer is not None:
            writer.release()
        tracker.close()
        env.close()
    return frames
