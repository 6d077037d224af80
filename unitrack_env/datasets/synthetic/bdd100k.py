"""A synthetic BDD100K box-tracking split in the exact layout, with detections in the result format.

The shared synthetic scenes (:func:`~unitrack_env.datasets.synthetic.scene.render_scene`) and
detector (:func:`~unitrack_env.datasets.synthetic.motchallenge.simulate_detections`), labelled
with BDD100K's classes: each walking object gets one of the 8 classes (the two of a forced
crossing share one), the standing person is an ``other person`` (a distractor category: an
ignore region), the last walking object of each video is a ``crowd`` box, and the occluder is
not labelled. Detections take their object's class (the standing person's are
``pedestrian``, false positives ``car``). Not benchmark data: it exercises the reader and
scoring and lets ``gym.make("UniTrack/BDD100K-v0")`` run offline.

``images/track/val/<video>/<video>-%07d.jpg``, ``labels/box_track_20/val/<video>.json``,
``detections/box_track_20/val/<video>.json``.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from unitrack_env.datasets.synthetic.cache import SyntheticKind
from unitrack_env.datasets.synthetic.motchallenge import DetectionNoise, simulate_detections
from unitrack_env.datasets.synthetic.scene import render_scene
from unitrack_env.datasets.synthetic.scene_model import (
    ObjectAnnotation,
    ObjectRole,
    SceneConfig,
)

BENCHMARKS = ("BDD100K",)
SPLIT = "val"
#: The videos: name and scene (BDD100K's frames are 1280x720; these are half as large).
VIDEOS = (
    ("5y7e71c0-00000001", SceneConfig(width=640, height=360, num_frames=24, num_objects=7,
                                      seed=41)),
    ("5y7e71c0-00000002", SceneConfig(width=640, height=360, num_frames=20, num_objects=6,
                                      seed=42)),
)
#: Classes given to walking objects, in turn, one per crossing pair.
_CLASS_TURN = ("car", "pedestrian", "truck", "rider", "bus", "motorcycle", "bicycle", "train")
#: Seed-stream index of the detections (as the MOTChallenge writer's).
_STREAM_DETECTIONS = 2


def _categories(objects: list[ObjectAnnotation], index: int) -> dict[int, tuple[str, bool]]:
    """``{object id: (category, crowd)}`` of a video's objects (occluders left out)."""
    walking = sorted({o.id for o in objects if o.role is ObjectRole.PEDESTRIAN})
    out = {ident: (_CLASS_TURN[((ident - 1) // 2 + index) % len(_CLASS_TURN)], False)
           for ident in walking}
    if walking:
        out[walking[-1]] = (out[walking[-1]][0], True)
    out.update({o.id: ("other person", False) for o in objects
                if o.role is ObjectRole.STATIC_PERSON})
    return out


def _clipped(box: tuple[float, ...], width: int, height: int) -> dict[str, float] | None:
    """``(x, y, w, h)`` clipped to the image as BDD's ``box2d`` (None when nothing is inside)."""
    x, y, w, h = (float(v) for v in box)
    x1, y1 = max(x, 0.0), max(y, 0.0)
    x2, y2 = min(x + w, width - 1.0), min(y + h, height - 1.0)
    if x2 - x1 < 2 or y2 - y1 < 2:
        return None
    return {"x1": round(x1, 2), "y1": round(y1, 2), "x2": round(x2, 2), "y2": round(y2, 2)}


def _xyxy(box: np.ndarray | tuple[float, ...]) -> dict[str, float]:
    """``(x, y, w, h)`` as BDD's ``box2d``."""
    x, y, w, h = (float(v) for v in box)
    return {"x1": round(x, 2), "y1": round(y, 2), "x2": round(x + w, 2), "y2": round(y + h, 2)}


def _frame(video: str, t: int, labels: list[dict]) -> dict:
    return {"name": f"{video}-{t + 1:07d}.jpg", "videoName": video, "frameIndex": t,
            "labels": labels}


def _video(root: Path, video: str, scene: SceneConfig, index: int) -> None:
    frames = root / "images" / "track" / SPLIT / video
    frames.mkdir(parents=True, exist_ok=True)
    annotations, gt = [], []
    rendered = list(render_scene(scene))
    classes = _categories([o for f in rendered for o in f.objects], index)
    for t, frame in enumerate(rendered):
        path = frames / f"{video}-{t + 1:07d}.jpg"
        if not cv2.imwrite(str(path), frame.image[:, :, ::-1], [cv2.IMWRITE_JPEG_QUALITY, 90]):
            raise OSError(f"{path}: cv2.imwrite failed to write the JPEG frame")
        annotations.append(frame.objects)
        labels = []
        for obj in frame.objects:
            box = _clipped(obj.box, scene.width, scene.height)
            if obj.id not in classes or box is None:
                continue
            category, crowd = classes[obj.id]
            labels.append({"id": f"{index + 1}{obj.id:07d}", "category": category,
                           "attributes": {"occluded": obj.visibility < 0.5,
                                          "truncated": box != _xyxy(obj.box), "crowd": crowd},
                           "box2d": box})
        gt.append(_frame(video, t, labels))
    found = simulate_detections(annotations, (scene.width, scene.height), DetectionNoise(),
                                np.random.default_rng([scene.seed, _STREAM_DETECTIONS]))
    dets = [_frame(video, t, []) for t in range(scene.num_frames)]
    for k, (t, box, score, source) in enumerate(zip(found.frames, found.boxes, found.scores,
                                                    found.sources, strict=True)):
        category = classes.get(int(source), ("car", False))[0]
        dets[int(t)]["labels"].append({
            "id": str(k), "category": "pedestrian" if category == "other person" else category,
            "box2d": _xyxy(box), "score": round(float(score), 4)})
    for folder, content in (("labels", gt), ("detections", dets)):
        out = root / folder / "box_track_20" / SPLIT
        out.mkdir(parents=True, exist_ok=True)
        (out / f"{video}.json").write_text(json.dumps(content), encoding="utf-8")


def write_bdd100k(root: Path, benchmark: str = "BDD100K") -> None:
    """Write the synthetic split under ``root`` (``images/``, ``labels/``, ``detections/``)."""
    for index, (video, scene) in enumerate(VIDEOS):
        _video(Path(root), video, scene, index)


def annotated_frames(benchmark: str, split: str | None = None) -> dict[str, int]:
    """The frames of each annotated video."""
    if split not in (None, SPLIT):
        return {}
    return {video: scene.num_frames for video, scene in VIDEOS}


KIND = SyntheticKind("bdd100k", write_bdd100k, BENCHMARKS, annotated_frames)
