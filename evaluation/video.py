"""Render an agent's episode to a video file (``unitrack render``).

``.mp4`` files are H.264 (``libx264``, ``yuv420p``: what browsers and players play), written
through the FFmpeg that ships inside the ``imageio-ffmpeg`` wheel (the ``video`` extra:
``pip install 'unitrack-env[video]'``). ``.avi`` files are Motion-JPEG through OpenCV and
need no extra.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

import cv2
import gymnasium as gym
import numpy as np

import unitrack_env
from unitrack_env.agents.base import close_agent, make_agent
from unitrack_env.io import file_in_the_way

from .run.episode import play_episode

#: Video extensions and how they are written.
FORMATS = {".mp4": "H.264 (imageio-ffmpeg)", ".avi": "Motion-JPEG (OpenCV)"}


def _even(image: np.ndarray) -> np.ndarray:
    """Pad to even width and height (H.264 in yuv420p needs both even)."""
    height, width = image.shape[:2]
    pad_h, pad_w = height % 2, width % 2
    if not (pad_h or pad_w):
        return image
    return np.pad(image, ((0, pad_h), (0, pad_w), (0, 0)))


class _H264Writer:
    def __init__(self, path: Path, size: tuple[int, int], fps: float) -> None:
        import imageio_ffmpeg  # lazy: optional dependency (imageio-ffmpeg, [video])

        self._gen = imageio_ffmpeg.write_frames(
            str(path), size, fps=fps, codec="libx264", pix_fmt_out="yuv420p", quality=None,
            macro_block_size=1, output_params=["-crf", "20", "-movflags", "+faststart"],
        )
        self._gen.send(None)

    def write(self, rgb: np.ndarray) -> None:
        self._gen.send(np.ascontiguousarray(rgb))

    def close(self) -> None:
        self._gen.close()


class _MJPGWriter:
    def __init__(self, path: Path, size: tuple[int, int], fps: float) -> None:
        self._writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, size)
        if not self._writer.isOpened():
            raise OSError(f"{path}: OpenCV could not open a video writer")

    def write(self, rgb: np.ndarray) -> None:
        self._writer.write(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))

    def close(self) -> None:
        self._writer.release()


def _check_writable(out: Path) -> None:
    """Refuse a video path whose folder cannot take a new file (read-only folder or disk).

    Probed by creating and deleting a file where the video (or its first missing folder)
    would go: permission bits do not tell (root ignores them; a read-only mount has them),
    and FFmpeg failing to open its output only shows as a broken pipe after the first frame.
    """
    existing = next(p for p in (out.parent, *out.parent.parents) if p.exists())
    try:
        with tempfile.NamedTemporaryFile(dir=existing, prefix=".unitrack-probe-"):
            pass
    except OSError as exc:
        raise ValueError(f"cannot write {out}: the folder {existing} is not writable "
                         f"({exc.strerror or exc}); choose another --out") from None
    if out.exists() and not os.access(out, os.W_OK):
        raise ValueError(f"cannot write {out}: the file exists and is not writable")


def check_video_path(out: str | os.PathLike) -> Path:
    """Validate the output path and the installed writer before any frame is played."""
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in FORMATS:
        raise ValueError(f"{out}: video extension must be one of {sorted(FORMATS)}")
    if out.is_dir():
        raise ValueError(f"{out} is a folder; give the video's file name ({out / 'episode.mp4'})")
    blocker = file_in_the_way(out.parent)
    if blocker is not None:
        raise ValueError(f"cannot write {out}: {blocker} is a file, not a folder")
    _check_writable(out)
    if suffix == ".mp4":
        try:
            import imageio_ffmpeg  # noqa: F401  # lazy: optional dependency (imageio-ffmpeg, [video])
        except ImportError:
            raise ImportError(
                "writing .mp4 (H.264) needs imageio-ffmpeg: pip install 'unitrack-env[video]' "
                "(or write .avi, which needs nothing more)"
            ) from None
    return out


def video_codec(path: str | os.PathLike) -> str:
    """The codec of a video file's first video stream, as FFmpeg names it (e.g. ``h264``)."""
    import imageio_ffmpeg  # lazy: optional dependency (imageio-ffmpeg, [video])

    reader = imageio_ffmpeg.read_frames(str(path))
    try:
        meta = next(reader)
    finally:
        reader.close()
    return str(meta.get("codec", "")).split()[0]


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
    out = check_video_path(out)
    unitrack_env.register_all()
    env = gym.make(env_id, render_mode="rgb_array", **(env_kwargs or {}))
    tracker = make_agent(agent, **(agent_kwargs or {}))
    writer: _H264Writer | _MJPGWriter | None = None
    frames = 0
    rate = fps

    def read_rate(info: dict[str, Any]) -> None:
        nonlocal rate
        rate = rate or float(info.get("frame_rate") or 25.0)

    def write_frame() -> None:
        nonlocal writer, frames
        image = _even(env.render())
        if writer is None:
            out.parent.mkdir(parents=True, exist_ok=True)
            kind = _H264Writer if out.suffix.lower() == ".mp4" else _MJPGWriter
            writer = kind(out, (image.shape[1], image.shape[0]), rate)
        writer.write(image)
        frames += 1

    try:
        play_episode(env, tracker, sequence, on_frame=write_frame, on_reset=read_rate)
    finally:
        if writer is not None:
            writer.close()
        close_agent(tracker)
        env.close()
    return frames
