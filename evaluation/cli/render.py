"""``unitrack render``: write a video of an agent's tracks on one sequence."""

from __future__ import annotations

import argparse

from rich.console import Console

from ..video import check_video_path, render_episode
from .common import agent_kwargs, env_kwargs, env_options, positive_float

EXAMPLES = """examples:
  unitrack render --env UniTrack/MOT16-v0 --agent iou --sequence SYN-01 --out syn01.mp4
"""


def add_arguments(rd: argparse.ArgumentParser) -> None:
    """The options of ``unitrack render``."""
    env_options(rd)
    rd.add_argument("--sequence", required=True,
                    help="the sequence to play (its name in the data set, e.g. MOT17-04-FRCNN)")
    rd.add_argument("--out", required=True,
                    help="video file: .mp4 (H.264, needs the video extra) or .avi (MJPEG)")
    rd.add_argument("--fps", type=positive_float, default=None,
                    help="video frame rate (default: the sequence's)")


def run(args: argparse.Namespace, console: Console) -> int:
    """Run ``unitrack render``."""
    check_video_path(args.out)
    frames = render_episode(args.env, args.agent, args.sequence, args.out,
                            env_kwargs=env_kwargs(args), agent_kwargs=agent_kwargs(args),
                            fps=args.fps)
    console.print(f"wrote {frames} frames to {args.out}", markup=False)
    return 0
