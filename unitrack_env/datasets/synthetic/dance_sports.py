"""Synthetic DanceTrack and SportsMOT data sets in their exact layouts, with detections.

The synthetic MOT scenes (:func:`~unitrack_env.datasets.synthetic.scene.render_scene`)
written as the real data sets are laid out (facts and sources in
:mod:`unitrack_env.datasets.mot_layouts`):

- DanceTrack: ``<root>/{train,val,test}/dancetrack000N/{img1/00000001.jpg, gt/gt.txt,
  seqinfo.ini}`` (no gt in test) and ``<root>/{train,val,test}_seqmap.txt``. Every dancer
  wears the same costume (the benchmark's point: uniform appearance) and sways in large,
  quick loops that change direction (diverse motion); no standers, no occluders.
- SportsMOT: ``<root>/dataset/{train,val,test}/v_SYNTHsports_c00N/{img1/000001.jpg,
  gt/gt.txt, seqinfo.ini}`` and ``<root>/splits_txt/{train,val,test}.txt``. Two teams in
  two kits move fast; a standing referee is detected but, as in SportsMOT, not annotated.

Neither benchmark ships detections; the simulated detector's go to
``<root>/detections/<split>/<sequence>.txt`` (det.txt format), where the reader looks for
the user's own (:data:`unitrack_env.datasets.motchallenge.DETECTIONS_FOLDER`).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from types import MappingProxyType

import cv2
import numpy as np

from unitrack_env.datasets.mot_layouts import LAYOUTS
from unitrack_env.datasets.synthetic.cache import SyntheticKind
from unitrack_env.datasets.synthetic.motchallenge import (
    DetectionNoise,
    SequenceSpec,
    write_sequence,
)
from unitrack_env.datasets.synthetic.scene import SyntheticVideo, render_scene
from unitrack_env.datasets.synthetic.scene_model import ObjectRole, SceneConfig

BENCHMARKS = ("DanceTrack", "SportsMOT")
#: Seed-stream index of the costume draws (the scene uses 0, 1; detections 2; hard MOT 3).
_STREAM_COSTUMES = 4


def _dance(num_frames: int, num_objects: int, seed: int) -> SceneConfig:
    return SceneConfig(width=640, height=360, num_frames=num_frames, num_objects=num_objects,
                       num_crossings=2, num_static_persons=0, num_occluders=0, seed=seed,
                       speed_range=(0.3, 1.2), wobble_amplitude=14.0,
                       wobble_period_range=(14.0, 30.0), max_vertical_speed=0.6)


def _sports(num_frames: int, num_objects: int, seed: int) -> SceneConfig:
    return SceneConfig(width=640, height=360, num_frames=num_frames, num_objects=num_objects,
                       num_crossings=2, num_static_persons=1, num_occluders=0, seed=seed,
                       speed_range=(2.5, 5.0), wobble_amplitude=4.0,
                       object_height_range=(70.0, 110.0))


#: Benchmark -> (sequences, number of kits). DanceTrack runs at 20 FPS, SportsMOT at 25
#: (their papers).
SPECS = MappingProxyType({
    "DanceTrack": ((SequenceSpec("dancetrack0001", "train", _dance(48, 6, 11), 20),
                    SequenceSpec("dancetrack0004", "val", _dance(40, 5, 12), 20),
                    SequenceSpec("dancetrack0003", "test", _dance(36, 5, 13), 20)), 1),
    "SportsMOT": ((SequenceSpec("v_SYNTHsports_c001", "train", _sports(48, 7, 21), 25),
                   SequenceSpec("v_SYNTHsports_c002", "val", _sports(40, 6, 22), 25),
                   SequenceSpec("v_SYNTHsports_c003", "test", _sports(36, 6, 23), 25)), 2),
})
"""The embedded defaults: one sequence per split (train and val annotated)."""


def _check(benchmark: str) -> None:
    if benchmark not in BENCHMARKS:
        raise ValueError(f"no synthetic {benchmark!r}; this writer makes {', '.join(BENCHMARKS)}")


def annotated_frames(benchmark: str, split: str | None = None) -> dict[str, int]:
    """Frames of each annotated sequence of ``split`` (None: any), known without writing."""
    _check(benchmark)
    return {s.name: s.scene.num_frames for s in SPECS[benchmark][0]
            if s.split != "test" and split in (None, s.split)}


def costumes(video: SyntheticVideo, kits: int, rng: np.random.Generator) -> SyntheticVideo:
    """Dress the people of ``video`` in ``kits`` costumes, assigned in turn.

    Each person keeps a costume's colours and pattern with its own pattern seed and a small
    angle nudge: look-alikes, as dancers in one costume or players of one team.
    """
    persons = [o for o in video.objects if o.role is not ObjectRole.OCCLUDER]
    kit_textures = [persons[k].texture for k in range(min(kits, len(persons)))]
    objects = []
    for obj in video.objects:
        if obj.role is not ObjectRole.OCCLUDER and kit_textures:
            base = kit_textures[persons.index(obj) % len(kit_textures)]
            obj = replace(obj, texture=replace(
                base, seed=base.seed + obj.id,
                angle=base.angle + float(rng.uniform(-0.1, 0.1))))
        objects.append(obj)
    return SyntheticVideo(video.config, tuple(objects), np.array(video.background))


def _seqmap_text(benchmark: str, names: list[str]) -> str:
    header = ["name"] if benchmark == "DanceTrack" else []  # DanceTrack's seqmaps have one
    return "".join(f"{line}\n" for line in [*header, *names])


def write_dance_sports(root: str | Path, benchmark: str) -> None:
    """Write the synthetic ``benchmark`` (DanceTrack or SportsMOT) under ``root``."""
    _check(benchmark)
    root = Path(root)
    layout = LAYOUTS[benchmark]
    sequences, kits = SPECS[benchmark]
    params = [cv2.IMWRITE_JPEG_QUALITY, 90]
    for seq in sequences:
        rng = np.random.default_rng([seq.scene.seed, _STREAM_COSTUMES])
        video = costumes(render_scene(seq.scene), kits, rng)
        write_sequence(layout.split_dir(root, seq.split) / seq.name, seq, video, benchmark,
                       DetectionNoise(), params, frame_digits=layout.frame_digits,
                       det_path=root / "detections" / seq.split / f"{seq.name}.txt")
    for split in layout.splits:
        seqmap = layout.seqmap_path(root, split)
        if seqmap is not None:
            seqmap.parent.mkdir(parents=True, exist_ok=True)
            seqmap.write_text(_seqmap_text(benchmark, [s.name for s in sequences
                                                       if s.split == split]), encoding="ascii")


KIND = SyntheticKind("dance_sports", write_dance_sports, BENCHMARKS, annotated_frames)
"""The generator of the embedded DanceTrack and SportsMOT defaults."""
