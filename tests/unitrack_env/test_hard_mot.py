"""The hard synthetic MOT scenes: look-alikes, a moving camera, the MOTChallenge layout."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.datasets.synthetic.hard_mot import (
    HARD_SPEC,
    CameraMotion,
    HardMotSpec,
    HardSequenceSpec,
    render_hard_sequence,
    write_hard_motchallenge,
)
from unitrack_env.datasets.synthetic.motchallenge import SequenceSpec
from unitrack_env.datasets.synthetic.scene import render_scene
from unitrack_env.datasets.synthetic.scene_model import ObjectRole, SceneConfig


def _tiny(camera: CameraMotion | None = None, lookalikes: int = 2) -> HardSequenceSpec:
    scene = SceneConfig(width=160, height=96, num_frames=6, num_objects=4, num_crossings=2,
                        num_static_persons=0, num_occluders=1, seed=7,
                        object_height_range=(30.0, 40.0), occluder_height_fraction=(0.3, 0.4))
    return HardSequenceSpec(SequenceSpec("TINY", "train", scene, frame_rate=30),
                            lookalikes=lookalikes, camera=camera)


def test_hard_spec_is_long_30fps_and_hard() -> None:
    for hard in HARD_SPEC.sequences:
        assert hard.sequence.frame_rate == 30 and hard.sequence.scene.num_frames >= 300
        assert hard.sequence.scene.num_crossings >= 3 and hard.lookalikes >= 2
    assert sum(h.camera is not None for h in HARD_SPEC.sequences) >= 2


def test_lookalikes_copy_a_crossing_partners_colours() -> None:
    from unitrack_env.datasets.synthetic.hard_mot import _lookalike_video

    video = render_scene(_tiny().sequence.scene)
    alike = _lookalike_video(video, 2, np.random.default_rng(0))
    by_id = {o.id: o.texture for o in alike.objects}
    # Crossing partners (1, 2) and (3, 4): the second of each pair wears the first's colours
    # and pattern (another phase), which the plain scene does not.
    for a, b in ((1, 2), (3, 4)):
        assert by_id[b].colour_a == by_id[a].colour_a
        assert by_id[b].pattern is by_id[a].pattern
        assert video.object(b).texture.colour_a != video.object(a).texture.colour_a
    image = alike.frame(0).image
    assert image.shape == video.frame(0).image.shape


def test_camera_moves_the_boxes_and_keeps_the_frame_size() -> None:
    camera = CameraMotion(margin=40, margin_y=8, pan_amplitude=15.0, pan_period=6.0,
                          shake_amplitude=2.0, shake_period=5.0)
    still = list(render_hard_sequence(_tiny(None, lookalikes=0)))
    moving = list(render_hard_sequence(_tiny(camera, lookalikes=0)))
    assert all(f.image.shape == (96, 160, 3) for f in moving)
    assert all(f.instance_map.shape == (96, 160) for f in moving)
    for frame in moving:
        for obj in frame.objects:
            assert 0.0 <= obj.visibility <= 1.0
            x, y, w, h = obj.box
            assert x < 160 and y < 96 and x + w > 0 and y + h > 0
    # The same static occluder appears at different image positions as the camera pans.
    def occluder_x(frames):
        return [o.box[0] for f in frames for o in f.objects if o.role is ObjectRole.OCCLUDER]
    assert len(set(occluder_x(moving))) > 1
    assert len(set(occluder_x(still))) == 1


def test_rendering_is_deterministic() -> None:
    spec = _tiny(CameraMotion(margin=40, margin_y=8))
    a = [f.image for f in render_hard_sequence(spec)]
    b = [f.image for f in render_hard_sequence(spec)]
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))


def test_written_layout_reads_in_the_mot17_environment(tmp_path: Path) -> None:
    spec = HardMotSpec(sequences=(_tiny(CameraMotion(margin=40, margin_y=8)),))
    write_hard_motchallenge(tmp_path, "MOT17", spec=spec)
    seq = tmp_path / "train" / "TINY"
    assert (seq / "gt" / "gt.txt").stat().st_size > 0
    assert len(list((seq / "img1").glob("*.jpg"))) == 6
    env = gym.make("UniTrack/MOT17-v0", root=tmp_path)
    obs, info = env.reset()
    assert info["frame_rate"] == 30 and obs["frame"].shape == (96, 160, 3)
    done = False
    while not done:
        obs, _, done, _, info = env.step({"ids": np.zeros(0, np.int64), "boxes": np.zeros((0, 4))})
    assert "HOTA" in info["metrics"]
    env.close()


def test_default_spec_is_untouched() -> None:
    from unitrack_env.datasets.synthetic.motchallenge import DEFAULT_SPEC

    assert [s.name for s in DEFAULT_SPEC.sequences] == ["SYN-01", "SYN-02", "SYN-03"]
    assert replace(HARD_SPEC).sequences[0].sequence.name == "HARD-01"
