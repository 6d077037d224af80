"""Every environment decodes frames through one helper: a frame whose size differs from the
size the data set states is a DataFormatError naming the file (checked on two layouts)."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np
import pytest

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.errors import DataFormatError


def _play_until_error(env: gym.Env, sequence: str, frames: int) -> None:
    obs, _ = env.reset(options={"sequence": sequence})
    for _ in range(frames):
        obs, *_ = env.step(env.action_space.sample())


@pytest.mark.parametrize(("env_id", "frame_glob", "source"), [
    ("UniTrack/OTB-v0", "img/0003.jpg", "first frame"),
    ("UniTrack/MOT17-v0", "img1/000003.jpg", "seqinfo.ini"),
])
def test_a_frame_of_the_wrong_size_names_the_file(tmp_path, env_id, frame_glob, source):
    default = gym.make(env_id).unwrapped
    root = Path(default.dataset.root)
    sequence = default.sequence_names[0]
    copy = tmp_path / root.name
    shutil.copytree(root, copy)
    target = next(copy.rglob(f"{sequence}/{frame_glob}"))
    cv2.imwrite(str(target), np.zeros((10, 12, 3), np.uint8))
    env = gym.make(env_id, root=str(copy))
    with pytest.raises(DataFormatError, match=rf"{target.name}.*image is 12x10 but .*{source}"):
        _play_until_error(env, sequence, 4)
