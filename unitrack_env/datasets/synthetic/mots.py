"""Synthetic MOTS data sets in the MOTS20 and KITTI MOTS layouts (:func:`write_mots`).

Ground truth comes from the rendered instance map, so masks never overlap: every person
(walking or standing) is a pedestrian (class 2, id ``2000 + object id``) and the occluder is
an ignore region (class 10, id 10000). Detections are the visible masks made imperfect
(:class:`MaskNoise`) plus false-positive blobs, some on the occluder, that is inside the
ignore region; overlaps between detections go to the higher score, as MOTS requires.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from unitrack_env.datasets.mots_format import (
    CLASS_IGNORE,
    CLASS_PEDESTRIAN,
    ID_CLASS_DIVISOR,
    IGNORE_ID,
    MaskAnnotations,
    format_instances_txt,
    write_instances_png,
)
from unitrack_env.datasets.rle import encode_masks, resolve_overlaps
from unitrack_env.datasets.synthetic.motchallenge import SequenceSpec
from unitrack_env.datasets.synthetic.scene import render_scene
from unitrack_env.datasets.synthetic.scene_model import ObjectRole, SceneConfig

#: Benchmarks (layouts) written by :func:`write_mots`.
BENCHMARKS = ("MOTS20", "KITTI-MOTS")
#: Roles annotated as pedestrians.
PERSON_ROLES = frozenset({ObjectRole.PEDESTRIAN, ObjectRole.STATIC_PERSON})
#: Seed-stream index of the detection noise (the scene uses 0 and 1).
_STREAM_DETECTIONS = 3


@dataclass(frozen=True)
class MaskNoise:
    """How simulated mask detections deviate from the ground truth.

    Misses as for boxes (``miss_rate + occlusion_miss_weight * (1 - v) ** 2``); masks are
    dilated or eroded by up to ``max_morph`` and shifted by up to ``max_shift`` pixels; scores
    ``score_base + score_visibility * v`` plus noise; Poisson false-positive blobs, some on the
    occluder; masks under ``min_pixels`` are dropped.
    """

    miss_rate: float = 0.04
    occlusion_miss_weight: float = 0.96
    max_morph: int = 2
    max_shift: int = 2
    score_base: float = 0.55
    score_visibility: float = 0.4
    score_noise: float = 0.05
    false_positives_per_frame: float = 0.3
    occluder_false_positive_rate: float = 0.2
    false_positive_score: tuple[float, float] = (2.0, 5.0)
    min_pixels: int = 20


@dataclass(frozen=True)
class MOTSSpec:
    """A synthetic MOTS data set: sequences (``split`` ``"train"``/``"test"``) and noise."""

    sequences: tuple[SequenceSpec, ...]
    noise: MaskNoise = field(default_factory=MaskNoise)
    jpeg_quality: int = 90


#: The embedded default: two train sequences (different sizes and frame rates) and one test.
DEFAULT_SPEC = MOTSSpec(sequences=(
    SequenceSpec("SYN-01", "train", SceneConfig(
        width=480, height=272, num_frames=40, num_objects=6, seed=11,
        object_height_range=(70.0, 110.0)), frame_rate=30),
    SequenceSpec("SYN-02", "train", SceneConfig(
        width=432, height=240, num_frames=36, num_objects=5, seed=12,
        object_height_range=(65.0, 100.0)), frame_rate=25),
    SequenceSpec("SYN-03", "test", SceneConfig(
        width=480, height=272, num_frames=30, num_objects=6, seed=13,
        object_height_range=(70.0, 110.0)), frame_rate=30),
))

#: The split whose sequences have ground truth.
ANNOTATED_SPLIT = "train"


def split_folder(benchmark: str, split: str) -> str:
    """The folder (and reader split) of ``split``: KITTI MOTS says training / testing."""
    return ({"train": "training", "test": "testing"}[split] if benchmark == "KITTI-MOTS"
            else split)


def annotated_frames(benchmark: str = "MOTS20", split: str | None = None,
                     spec: MOTSSpec = DEFAULT_SPEC) -> dict[str, int]:
    """Frames of each sequence of ``split`` (None: any; a reader's split name) with ground truth.

    Known without writing anything, e.g. to plan work on data not generated yet.
    """
    return {s.name: s.scene.num_frames for s in spec.sequences if s.split == ANNOTATED_SPLIT
            and split in (None, split_folder(benchmark, s.split))}


def _morph(mask: np.ndarray, amount: int) -> np.ndarray:
    if amount == 0:
        return mask
    kernel = np.ones((2 * abs(amount) + 1, 2 * abs(amount) + 1), np.uint8)
    op = cv2.dilate if amount > 0 else cv2.erode
    return op(mask.astype(np.uint8), kernel).astype(bool)


def _shift(mask: np.ndarray, dx: int, dy: int) -> np.ndarray:
    out = np.zeros_like(mask)
    h, w = mask.shape
    ys, yd = (slice(0, h - dy), slice(dy, h)) if dy >= 0 else (slice(-dy, h), slice(0, h + dy))
    xs, xd = (slice(0, w - dx), slice(dx, w)) if dx >= 0 else (slice(-dx, w), slice(0, w + dx))
    out[yd, xd] = mask[ys, xs]
    return out


def _blob(rng: np.random.Generator, shape: tuple[int, int], centre: tuple[float, float] | None
          ) -> np.ndarray:
    h, w = shape
    axes = (int(rng.uniform(6, 18)), int(rng.uniform(12, 35)))
    if centre is None:
        centre = (rng.uniform(0, w), rng.uniform(0, h))
    mask = np.zeros(shape, np.uint8)
    cv2.ellipse(mask, (int(centre[0]), int(centre[1])), axes, 0, 0, 360, 1, -1)
    return mask.astype(bool)


@dataclass
class FrameMasks:
    """One frame's ground truth and detections as mask stacks (for writers and tests)."""

    gt_ids: np.ndarray
    gt_masks: np.ndarray
    ignore: np.ndarray | None
    det_masks: np.ndarray
    det_scores: np.ndarray
    det_classes: np.ndarray
    det_sources: np.ndarray


def simulate_frame(frame, noise: MaskNoise, rng: np.random.Generator, *,
                   resolve: bool = True, class_noise: float = 0.0) -> FrameMasks:
    """Ground truth and noisy detections (:class:`FrameMasks`) of one rendered frame.

    ``resolve`` makes detection masks disjoint (MOTS); ``class_noise`` flips a detection's class
    (VIS: 1 person, 2 occluder object); ``det_sources`` is -1 for false positives. A fixed
    number of draws per object keeps the random streams aligned.
    """
    imap = frame.instance_map
    shape = imap.shape
    gt_ids, gt_masks, ignore = [], [], None
    dets = _MaskDetections()
    occluder_masks = []
    for obj in frame.objects:
        mask = imap == obj.id
        draws = rng.uniform(size=6)
        if obj.role is ObjectRole.OCCLUDER:
            if mask.sum() >= noise.min_pixels:
                occluder_masks.append((obj.id, mask))
            continue
        if obj.role not in PERSON_ROLES or obj.visible_pixels < noise.min_pixels:
            continue
        gt_ids.append(obj.id)
        gt_masks.append(mask)
        p_miss = noise.miss_rate + noise.occlusion_miss_weight * (1 - obj.visibility) ** 2
        if draws[0] < p_miss:
            continue
        amount = int(round((draws[1] * 2 - 1) * noise.max_morph))
        dx = int(round((draws[2] * 2 - 1) * noise.max_shift))
        dy = int(round((draws[3] * 2 - 1) * noise.max_shift))
        score = noise.score_base + noise.score_visibility * obj.visibility + \
            noise.score_noise * (draws[4] * 2 - 1) * 1.7
        dets.add(_shift(_morph(mask, amount), dx, dy), float(np.clip(score, 0.01, 0.999)),
                 2 if draws[5] < class_noise else 1, obj.id)
    for obj_id, mask in occluder_masks:
        ignore = mask if ignore is None else ignore | mask
        _occluder_detections(dets, obj_id, mask, noise, rng, class_noise)
    for _ in range(rng.poisson(noise.false_positives_per_frame)):
        dets.add(_blob(rng, shape, None), float(rng.beta(*noise.false_positive_score)),
                 int(rng.integers(1, 3)), -1)
    return dets.frame_masks(gt_ids, gt_masks, ignore, shape, noise.min_pixels, resolve)


def _occluder_detections(
    dets: _MaskDetections, obj_id: int, mask: np.ndarray, noise: MaskNoise,
    rng: np.random.Generator, class_noise: float,
) -> None:
    """Detections on an occluder: a person-like false positive, and (VIS) the object itself."""
    draws = rng.uniform(size=3)
    if draws[0] < noise.occluder_false_positive_rate:  # a person-like false positive on it
        ys, xs = np.nonzero(mask)
        centre = (float(xs.mean()), float(ys.mean()))
        dets.add(_blob(rng, mask.shape, centre) & mask,
                 float(rng.beta(*noise.false_positive_score)), 1, -1)
    if class_noise > 0 and draws[1] < 0.9:  # VIS: the occluder is an object of class 2
        dets.add(_morph(mask, int(round(draws[2] * 2 - 1))),
                 float(np.clip(0.6 + 0.3 * draws[2], 0.01, 0.999)), 2, obj_id)


class _MaskDetections:
    """One frame's detections, collected in drawing order."""

    def __init__(self) -> None:
        self.masks: list[np.ndarray] = []
        self.scores: list[float] = []
        self.classes: list[int] = []
        self.sources: list[int] = []

    def add(self, mask: np.ndarray, score: float, cls: int, source: int) -> None:
        """Append one detection."""
        self.masks.append(mask)
        self.scores.append(score)
        self.classes.append(cls)
        self.sources.append(source)

    def frame_masks(self, gt_ids: list[int], gt_masks: list[np.ndarray],
                    ignore: np.ndarray | None, shape: tuple[int, ...], min_pixels: int,
                    resolve: bool) -> FrameMasks:
        """The frame's :class:`FrameMasks`: overlaps resolved if asked, tiny masks dropped."""
        det_masks = np.asarray(self.masks, dtype=bool).reshape(-1, *shape)
        det_scores = np.asarray(self.scores, dtype=np.float64)
        if resolve and len(det_masks):
            det_masks = resolve_overlaps(det_masks, det_scores)
        keep = det_masks.reshape(len(det_masks), -1).sum(axis=1) >= min_pixels
        return FrameMasks(
            gt_ids=np.asarray(gt_ids, dtype=np.int64),
            gt_masks=np.asarray(gt_masks, dtype=bool).reshape(-1, *shape),
            ignore=ignore,
            det_masks=det_masks[keep],
            det_scores=det_scores[keep],
            det_classes=np.asarray(self.classes, dtype=np.int64)[keep],
            det_sources=np.asarray(self.sources, dtype=np.int64)[keep],
        )


class _Rows:
    """Accumulates MOTS rows of one file."""

    def __init__(self) -> None:
        self.rows: list[tuple] = []
        self.counts: list[bytes] = []

    def add(self, t: int, ids, cls, masks: np.ndarray, scores=None) -> None:
        h, w = masks.shape[1:]
        for i, counts in enumerate(encode_masks(masks)):
            obj = ids[i] if np.ndim(ids) else ids
            c = cls[i] if np.ndim(cls) else cls
            s = 1.0 if scores is None else float(scores[i])
            self.rows.append((t, int(obj), int(c), h, w, s))
            self.counts.append(counts)

    def annotations(self) -> MaskAnnotations:
        if not self.rows:
            return MaskAnnotations.empty()
        arr = np.asarray(self.rows, dtype=np.float64)
        i = arr[:, :5].astype(np.int64)
        return MaskAnnotations(i[:, 0], i[:, 1], i[:, 2], i[:, 3], i[:, 4], tuple(self.counts),
                               arr[:, 5], np.zeros(len(arr), np.int64))


def _seqinfo(seq: SequenceSpec) -> str:
    s = seq.scene
    return (f"[Sequence]\nname={seq.name}\nimDir=img1\nframeRate={seq.frame_rate}\n"
            f"seqLength={s.num_frames}\nimWidth={s.width}\nimHeight={s.height}\nimExt=.jpg\n")


def write_mots(root: str | Path, benchmark: str, *, spec: MOTSSpec = DEFAULT_SPEC) -> None:
    """Render ``spec`` and write it under ``root`` in ``benchmark``'s layout."""
    if benchmark not in BENCHMARKS:
        raise ValueError(f"unknown MOTS benchmark {benchmark!r}; valid: {', '.join(BENCHMARKS)}")
    root = Path(root)
    kitti = benchmark == "KITTI-MOTS"
    first = 0 if kitti else 1
    for seq in spec.sequences:
        train = seq.split == ANNOTATED_SPLIT
        if kitti:
            split = split_folder(benchmark, seq.split)
            image_dir = root / split / "image_02" / seq.name
            det_file = root / split / "det_02" / f"{seq.name}.txt"
        else:
            seq_dir = root / seq.split / seq.name
            image_dir = seq_dir / "img1"
            det_file = seq_dir / "det" / "det.txt"
            (seq_dir / "gt").mkdir(parents=True, exist_ok=True)
            (seq_dir / "seqinfo.ini").write_text(_seqinfo(seq), encoding="ascii")
        image_dir.mkdir(parents=True, exist_ok=True)
        rng = np.random.default_rng([seq.scene.seed, _STREAM_DETECTIONS])
        gt, dets = _Rows(), _Rows()
        for frame in render_scene(seq.scene):
            t = frame.index + first
            ext = ".png" if kitti else ".jpg"
            params = [] if kitti else [cv2.IMWRITE_JPEG_QUALITY, int(spec.jpeg_quality)]
            path = image_dir / f"{t:06d}{ext}"
            if not cv2.imwrite(str(path), frame.image[:, :, ::-1], params):
                raise OSError(f"{path}: cv2.imwrite failed")
            fm = simulate_frame(frame, spec.noise, rng)
            gt.add(t, CLASS_PEDESTRIAN * ID_CLASS_DIVISOR + fm.gt_ids, CLASS_PEDESTRIAN,
                   fm.gt_masks)
            if fm.ignore is not None:
                gt.add(t, IGNORE_ID, CLASS_IGNORE, fm.ignore[None])
            dets.add(t, -1, CLASS_PEDESTRIAN, fm.det_masks, fm.det_scores)
        det_file.parent.mkdir(parents=True, exist_ok=True)
        det_file.write_text(format_instances_txt(dets.annotations(), with_scores=True),
                            encoding="ascii")
        if not train:
            continue
        ann = gt.annotations()
        if kitti:
            txt = root / "instances_txt" / f"{seq.name}.txt"
            txt.parent.mkdir(parents=True, exist_ok=True)
            txt.write_text(format_instances_txt(ann), encoding="ascii")
            frames = range(first, first + seq.scene.num_frames)
            write_instances_png(root / "instances" / seq.name, ann, frames,
                                (seq.scene.height, seq.scene.width))
        else:
            (root / seq.split / seq.name / "gt" / "gt.txt").write_text(
                format_instances_txt(ann), encoding="ascii")
