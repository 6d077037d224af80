"""TAP-Vid-Kinetics: the CSV reader, the clips decoded with OpenCV, and the environment."""

from __future__ import annotations

import shutil

import cv2
import gymnasium as gym
import numpy as np
import pytest

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.agents import make_agent
from unitrack_env.datasets.synthetic import render_scene
from unitrack_env.datasets.synthetic.cache import ensure_synthetic
from unitrack_env.datasets.synthetic.tapvid import KINETICS_LABEL, SPECS, point_tracks
from unitrack_env.datasets.tapvid_kinetics import (
    FRAMES_PER_ROW,
    KineticsDataset,
    decode_clip,
    fps_slots,
)
from unitrack_env.errors import DataFormatError

ENV = "UniTrack/TAPVid-Kinetics-v0"
NAMES = [spec.name for spec in SPECS["TAPVid-Kinetics"]]


@pytest.fixture()
def folder(tmp_path):
    """A writable copy of the synthetic Kinetics folder (CSV and clips)."""
    target = tmp_path / "kinetics"
    shutil.copytree(ensure_synthetic("TAPVid-Kinetics", kind="tapvid"), target)
    return target


def _row(youtube_id="abcdefghijk", start=10, end=20, frames=FRAMES_PER_ROW, visible=()):
    cells = [youtube_id, str(start), str(end)]
    for t in range(frames):
        cells += ["0.5", "0.25", "0"] if t in visible else ["0.0", "0.0", "1"]
    return cells


def _write_csv(path, rows):
    path.write_text("\n".join(",".join(row) for row in rows) + "\n")


def _write_clip(path, frames, fps=25.0, size=(32, 24)):
    """An mp4v clip whose frame ``i`` is a flat grey of level ``20 i`` (to recognise it)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, size)
    for i in range(frames):
        writer.write(np.full((size[1], size[0], 3), 20 * i % 256, np.uint8))
    writer.release()


def test_reader_gives_the_exact_synthetic_tracks_and_clip_frames():
    root = ensure_synthetic("TAPVid-Kinetics", kind="tapvid")
    full, raster = KineticsDataset(root), KineticsDataset(root, size=(256, 256))
    assert full.sequence_names == NAMES and full.missing == []
    for spec in SPECS["TAPVid-Kinetics"]:
        frames, xy, occluded = point_tracks(render_scene(spec.scene), spec.scene.seed)
        video = full.load(spec.name)
        # the clips are shorter than their 10 s segment: the annotations are cut to them
        assert video.points.shape == (len(xy), spec.scene.num_frames, 2)
        np.testing.assert_array_equal(video.occluded, occluded)
        size = np.array([spec.scene.width, spec.scene.height])
        np.testing.assert_allclose(video.points[~occluded], (xy / size)[~occluded], atol=1e-6)
        assert video.frames.shape == frames.shape  # mp4v is lossy, but close
        assert np.abs(video.frames.astype(int) - frames).mean() < 8
        assert raster.load(spec.name).frames.shape == (spec.scene.num_frames, 256, 256, 3)


#: Source frames that ``ffmpeg -i clip.mp4 -vf fps=25`` shows (measured with the ffmpeg
#: binary of imageio-ffmpeg 0.8.1 on mp4v clips of n frames at each rate).
FFMPEG_FPS25 = {
    (30.0, 12): [0, 1, 2, 4, 5, 6, 7, 8, 10, 11],
    (20.0, 12): [0, 1, 1, 2, 3, 4, 5, 5, 6, 7, 8, 9, 9, 10, 11],
    (29.97, 40): [0, 1, 2, 4, 5, 6, 7, 8, 10, 11, 12, 13, 14, 16, 17, 18, 19, 20, 22, 23, 24,
                  25, 26, 28, 29, 30, 31, 32, 34, 35, 36, 37, 38],
    (24.0, 30): [*range(12), *range(11, 30)],
    (25.0, 5): [0, 1, 2, 3, 4],
}


@pytest.mark.parametrize(("fps", "count"), list(FFMPEG_FPS25))
def test_fps_resampling_follows_ffmpeg_fps_filter(fps, count):
    assert fps_slots(np.arange(count) / fps, count / fps).tolist() == FFMPEG_FPS25[fps, count]


def test_a_30_fps_clip_is_decoded_at_25_fps(tmp_path):
    _write_clip(tmp_path / "c.mp4", 12, fps=30.0)
    frames, source = decode_clip(tmp_path / "c.mp4", None, 10)
    assert source == (32, 24) and frames.shape == (10, 24, 32, 3)
    levels = np.round(frames[:, 12, 16, 0] / 20.0).astype(int).tolist()
    assert levels == FFMPEG_FPS25[30.0, 12]


def test_a_video_plays_with_an_agent_in_both_query_modes():
    for mode in ("first", "strided"):
        env = gym.make(ENV, query_mode=mode)
        agent = make_agent("static-points")
        observation, info = env.reset(options={"sequence": NAMES[1]})
        assert info["frame_rate"] == 25 and info["num_frames"] == 16
        agent.reset(observation, info)
        done = False
        while not done:
            observation, _, terminated, truncated, info = env.step(agent.act(observation))
            done = terminated or truncated
        assert 0 < info["metrics"]["AJ"] <= 1
        assert env.unwrapped.sequence_inputs(NAMES[1])[0].name == "tapvid_kinetics.csv"


@pytest.mark.parametrize(("row", "line", "field", "says"), [
    (_row()[:-3], 2, None, "750 fields, expected 753"),
    (["youtube_id", "start_time_sec", *_row()[2:]], 2, "start_time_sec", "not an integer"),
    (_row()[:3] + ["0.5", "0.5", "2"] + _row()[6:], 2, "occluded[0]", "is not 0 or 1"),
    (_row()[:6] + ["nan", "0.5", "0"] + _row()[9:], 2, "x[1]", "not finite"),
    (_row()[:3] + ["0.5", "1.5", "0"] + _row()[6:], 2, "y[0]", "outside 0..1"),
    (_row(start=20, end=20), 2, "end_time_sec", "not 0 <= start < end"),
])
def test_malformed_rows_name_the_file_line_and_field(tmp_path, row, line, field, says):
    _write_csv(tmp_path / "tapvid_kinetics.csv", [_row(visible={0}), row])
    with pytest.raises(DataFormatError, match=says) as caught:
        KineticsDataset(tmp_path)
    assert caught.value.line == line and caught.value.field == field
    assert caught.value.path.name == "tapvid_kinetics.csv"


def test_a_missing_clip_names_its_expected_path_or_is_skipped_on_request(folder):
    (folder / KINETICS_LABEL / f"{NAMES[0]}.mp4").rename(folder / f"{NAMES[0]}.webm")
    with pytest.raises(DataFormatError, match="missing_clips='skip'") as caught:
        gym.make(ENV, root=folder)
    assert caught.value.path == folder / f"{NAMES[0]}.mp4"
    assert f"{NAMES[0]}.webm is there" in str(caught.value)
    env = gym.make(ENV, root=folder, missing_clips="skip")
    assert env.unwrapped.sequence_names == NAMES[1:]
    assert env.unwrapped.dataset.missing == NAMES[:1]


def test_clips_that_do_not_fit_their_annotations_are_refused_before_the_first_frame(tmp_path):
    clip = tmp_path / "label" / "abcdefghijk_000010_000020.mp4"
    # annotated visible at frame 100 (4 s), the clip holds 40 frames (1.6 s): partial
    _write_csv(tmp_path / "tapvid_kinetics.csv", [_row(visible={0, 100})])
    _write_clip(clip, 40)
    env = gym.make(ENV, root=tmp_path)
    with pytest.raises(DataFormatError, match="decodes to 40 frames .* visible at frame 100"):
        env.reset()
    # a clip longer than its 1 s segment by more than a second (2.4 s): the untrimmed video
    _write_csv(tmp_path / "tapvid_kinetics.csv", [_row(start=10, end=11, visible={0})])
    clip.unlink()
    _write_clip(clip.with_name("abcdefghijk_000010_000011.mp4"), 60)
    with pytest.raises(DataFormatError, match="untrimmed"):
        gym.make(ENV, root=tmp_path).reset()
    # bytes that are no video
    clip.with_name("abcdefghijk_000010_000011.mp4").write_bytes(b"not a video" * 10)
    with pytest.raises(DataFormatError, match="abcdefghijk_000010_000011.mp4: OpenCV"):
        gym.make(ENV, root=tmp_path).reset()


def test_kinetics_options_are_refused_for_the_pickle_data_sets():
    with pytest.raises(ValueError, match="TAP-Vid-Kinetics options"):
        gym.make("UniTrack/TAPVid-DAVIS-v0", missing_clips="skip")
