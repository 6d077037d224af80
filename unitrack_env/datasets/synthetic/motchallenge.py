"""Synthetic MOTChallenge data sets (MOT15, MOT16, MOT17, MOT20 layouts).

:func:`write_motchallenge` writes ``<split>/<SEQ>/{img1/, seqinfo.ini, gt/gt.txt,
det/det.txt}`` (no ``gt`` in test) with the benchmark's ground-truth columns and row order.
In MOT16/17/20 a standing person (class 7, a distractor) and the occluder (class 9) are
written with flag 0 as in the official MOT17 files, so that the official preprocessing
(distractor removal, zero-marked filtering) has work to do; visibility is measured on the
rendered instance map. The public detections (:func:`simulate_detections`) miss a person
more often the less visible it is and score in [0, 1] by box quality; MOT15's are scaled to
0-100 like the PETS detector's unbounded scores.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import cv2
import numpy as np

from unitrack_env.datasets.synthetic.scene import render_scene
from unitrack_env.datasets.synthetic.scene_model import (
    ObjectAnnotation,
    ObjectRole,
    SceneConfig,
    SyntheticFrame,
)
from unitrack_env.geometry import box_iou

#: Benchmarks whose layout :func:`write_motchallenge` writes.
BENCHMARKS = ("MOT15", "MOT16", "MOT17", "MOT20")
#: Benchmarks whose gt.txt has the 9-column class/visibility layout.
CLASS_COLUMN_BENCHMARKS = frozenset({"MOT16", "MOT17", "MOT20"})
#: ``(flag, class)`` written for each role in MOT16/17/20 ground truth; roles not listed
#: are not written. Class ids: 1 pedestrian, 7 static_person, 9 occluder.
MOT_CLASSES = MappingProxyType({
    ObjectRole.PEDESTRIAN: (1, 1),
    ObjectRole.STATIC_PERSON: (0, 7),
    ObjectRole.OCCLUDER: (0, 9),
})
#: Roles written to MOT15 ground truth (which has no classes; flag 1).
MOT15_ROLES = frozenset({ObjectRole.PEDESTRIAN, ObjectRole.STATIC_PERSON})
#: Benchmarks whose gt.txt lists only the tracked people, each ``1,1,1`` (flag, class 1,
#: visibility 1), in frame order: DanceTrack's and SportsMOT's READMEs show such rows.
TARGETS_ONLY_BENCHMARKS = frozenset({"DanceTrack", "SportsMOT"})
#: Roles a simulated person detector fires on.
DETECTABLE_ROLES = frozenset({ObjectRole.PEDESTRIAN, ObjectRole.STATIC_PERSON})
#: MOT15 detection scores are the [0, 1] score times this (PETS-like unbounded range).
MOT15_SCORE_SCALE = 100.0
#: Splits that ship ground truth.
SPLITS_WITH_GROUND_TRUTH = frozenset({"train", "val"})
#: Seed-stream index of the detection noise (the scene uses 0 and 1).
_STREAM_DETECTIONS = 2


@dataclass(frozen=True)
class DetectionNoise:
    """How simulated public detections deviate from the ground truth.

    A person with visibility ``v`` is missed with probability
    ``min(1, miss_rate + occlusion_miss_weight * (1 - v) ** occlusion_miss_power)``. A detected
    box keeps centre and size up to Gaussian noise (``position_jitter`` of the size,
    ``size_jitter`` of the log size, both times ``2 - v``), clipped to the image. Its score is
    ``score_base + score_iou * IoU + score_visibility * v`` plus ``score_noise``, clipped to
    [``min_score``, ``max_score``]. False positives: a Poisson number of random boxes per frame
    (Beta-distributed scores) and, with ``clutter_rate`` per person visible at least
    ``clutter_min_visibility``, a shifted or partial near-duplicate. Boxes under ``min_size``
    pixels are dropped.
    """

    miss_rate: float = 0.04
    occlusion_miss_weight: float = 0.96
    occlusion_miss_power: float = 2.0
    position_jitter: float = 0.04
    size_jitter: float = 0.06
    score_base: float = 0.25
    score_iou: float = 0.45
    score_visibility: float = 0.3
    score_noise: float = 0.06
    false_positives_per_frame: float = 0.4
    false_positive_height_range: tuple[float, float] = (40.0, 140.0)
    false_positive_aspect_range: tuple[float, float] = (0.3, 0.6)
    false_positive_score: tuple[float, float] = (2.0, 5.0)
    clutter_rate: float = 0.04
    clutter_min_visibility: float = 0.3
    min_size: float = 6.0
    min_score: float = 0.01
    max_score: float = 0.999


@dataclass(frozen=True)
class SequenceSpec:
    """One synthetic sequence (``split``: ``"train"``, ``"val"`` with gt, ``"test"`` without)."""

    name: str
    split: str
    scene: SceneConfig
    frame_rate: int = 30

    def __post_init__(self) -> None:
        if self.split not in ("train", "val", "test"):
            raise ValueError(f"SequenceSpec.split={self.split!r}: use 'train', 'val' or 'test'")
        if not self.name or "/" in self.name or "\\" in self.name:
            raise ValueError(f"SequenceSpec.name={self.name!r}: must be a plain folder name")
        if self.frame_rate <= 0:
            raise ValueError(f"SequenceSpec.frame_rate={self.frame_rate}: must be positive")


@dataclass(frozen=True)
class MotChallengeSpec:
    """A synthetic MOTChallenge data set: sequences, the simulated detector, JPEG quality."""

    sequences: tuple[SequenceSpec, ...]
    detection_noise: DetectionNoise = field(default_factory=DetectionNoise)
    jpeg_quality: int = 90

    def __post_init__(self) -> None:
        names = [(s.split, s.name) for s in self.sequences]
        if len(set(names)) != len(names):
            raise ValueError(f"MotChallengeSpec.sequences: duplicate split/name in {names}")
        if not 0 <= self.jpeg_quality <= 100:
            raise ValueError(f"MotChallengeSpec.jpeg_quality={self.jpeg_quality}: use 0..100")


#: The embedded default: two train sequences (one of another frame size and frame rate) and
#: one test sequence, each with two forced crossings, a standing person and an occluder.
DEFAULT_SPEC = MotChallengeSpec(sequences=(
    SequenceSpec("SYN-01", "train", SceneConfig(
        width=640, height=360, num_frames=72, num_objects=7, seed=1), frame_rate=30),
    SequenceSpec("SYN-02", "train", SceneConfig(
        width=576, height=324, num_frames=64, num_objects=6, seed=2), frame_rate=25),
    SequenceSpec("SYN-03", "test", SceneConfig(
        width=640, height=360, num_frames=80, num_objects=8, seed=3), frame_rate=30),
))


def annotated_frames(benchmark: str = "MOT17", split: str | None = None,
                     spec: MotChallengeSpec = DEFAULT_SPEC) -> dict[str, int]:
    """Frames of each sequence of ``split`` (None: any) that has ground truth.

    Known without writing anything, e.g. to plan work on data not generated yet.
    """
    return {s.name: s.scene.num_frames for s in spec.sequences
            if s.split in SPLITS_WITH_GROUND_TRUTH and split in (None, s.split)}


@dataclass(frozen=True)
class Detections:
    """Simulated detections of a sequence (``sources``: object id, -1 for false positives)."""

    frames: np.ndarray
    boxes: np.ndarray
    scores: np.ndarray
    sources: np.ndarray

    def __len__(self) -> int:
        return len(self.frames)


def _clip_box(box: np.ndarray, width: int, height: int) -> np.ndarray:
    x0, y0 = max(box[0], 0.0), max(box[1], 0.0)
    x1, y1 = min(box[0] + box[2], float(width)), min(box[1] + box[3], float(height))
    return np.array([x0, y0, x1 - x0, y1 - y0])


def simulate_detections(
    annotations: Sequence[Sequence[ObjectAnnotation]],
    image_size: tuple[int, int],
    noise: DetectionNoise,
    rng: np.random.Generator,
) -> Detections:
    """Make noisy detections (sorted by frame) from per-frame ground truth, clipped to the image."""
    width, height = image_size
    out = _DetectionList(width, height, noise)
    for t, objects in enumerate(annotations):
        for obj in objects:
            if obj.role in DETECTABLE_ROLES:
                out.add(t, *_true_detection(obj, noise, rng, width, height))
        for obj in objects:  # clutter: a shifted or partial box next to a visible person
            if obj.role not in DETECTABLE_ROLES or obj.visibility < noise.clutter_min_visibility:
                continue
            if rng.uniform() >= noise.clutter_rate:
                continue
            out.add(t, _clutter_box(obj, rng), float(rng.beta(*noise.false_positive_score)), -1)
        for _ in range(rng.poisson(noise.false_positives_per_frame)):
            h = rng.uniform(*noise.false_positive_height_range)
            w = h * rng.uniform(*noise.false_positive_aspect_range)
            box = np.array([rng.uniform(-0.2 * w, width - 0.8 * w),
                            rng.uniform(-0.2 * h, height - 0.8 * h), w, h])
            out.add(t, box, float(rng.beta(*noise.false_positive_score)), -1)
    return out.build()


class _DetectionList:
    """Detections collected frame by frame: clipped to the image, too small ones dropped."""

    def __init__(self, width: int, height: int, noise: DetectionNoise) -> None:
        self.width, self.height, self.noise = width, height, noise
        self.frames: list[int] = []
        self.boxes: list[np.ndarray] = []
        self.scores: list[float] = []
        self.sources: list[int] = []

    def add(self, t: int, box: np.ndarray | None, score: float, source: int) -> None:
        """Keep a detection (``box`` None: the object was missed)."""
        if box is None:
            return
        noise = self.noise
        box = _clip_box(box, self.width, self.height)
        if box[2] < noise.min_size or box[3] < noise.min_size:
            return
        self.frames.append(t)
        self.boxes.append(box)
        self.scores.append(float(np.clip(score, noise.min_score, noise.max_score)))
        self.sources.append(source)

    def build(self) -> Detections:
        """The detections, in the order they were added."""
        return Detections(
            frames=np.asarray(self.frames, dtype=np.int64),
            boxes=np.asarray(self.boxes, dtype=np.float64).reshape(-1, 4),
            scores=np.asarray(self.scores, dtype=np.float64),
            sources=np.asarray(self.sources, dtype=np.int64),
        )


def _true_detection(
    obj: ObjectAnnotation, noise: DetectionNoise, rng: np.random.Generator, width: int,
    height: int,
) -> tuple[np.ndarray | None, float, int]:
    """A jittered, scored detection of ``obj`` (box None when it is missed)."""
    v = obj.visibility
    p_miss = noise.miss_rate + noise.occlusion_miss_weight * (
        1.0 - v) ** noise.occlusion_miss_power
    draws = rng.standard_normal(5)  # always drawn: keeps the stream aligned
    if rng.uniform() < p_miss:
        return None, 0.0, obj.id
    x, y, w, h = obj.box
    spread = 2.0 - v
    cx = x + w / 2 + draws[0] * noise.position_jitter * w * spread
    cy = y + h / 2 + draws[1] * noise.position_jitter * h * spread
    dw = w * np.exp(draws[2] * noise.size_jitter * spread)
    dh = h * np.exp(draws[3] * noise.size_jitter * spread)
    box = np.array([cx - dw / 2, cy - dh / 2, dw, dh])
    iou = float(box_iou(_clip_box(box, width, height)[None], np.array([obj.box]))[0, 0])
    score = (noise.score_base + noise.score_iou * iou + noise.score_visibility * v
             + noise.score_noise * draws[4])
    return box, score, obj.id


def _clutter_box(obj: ObjectAnnotation, rng: np.random.Generator) -> np.ndarray:
    """A false positive next to ``obj``: shifted sideways, or its upper or lower part only."""
    x, y, w, h = obj.box
    if rng.uniform() < 0.5:  # shifted sideways by about a width
        shift = rng.choice([-1.0, 1.0]) * rng.uniform(0.6, 1.0) * w
        return np.array([x + shift, y + rng.uniform(-0.1, 0.1) * h, w, h])
    part = rng.uniform(0.3, 0.45)
    top = y if rng.uniform() < 0.5 else y + (1 - part) * h
    return np.array([x, top, w, part * h])


def _seqinfo_text(spec: SequenceSpec) -> str:
    scene = spec.scene
    return (
        "[Sequence]\n"
        f"name={spec.name}\n"
        "imDir=img1\n"
        f"frameRate={spec.frame_rate}\n"
        f"seqLength={scene.num_frames}\n"
        f"imWidth={scene.width}\n"
        f"imHeight={scene.height}\n"
        "imExt=.jpg\n"
    )


def _gt_lines(
    benchmark: str, annotations: Sequence[Sequence[ObjectAnnotation]]
) -> list[str]:
    """Ground-truth rows (1-based coordinates) in the benchmark's column layout and order."""
    rows: list[tuple[int, int, str]] = []
    for t, objects in enumerate(annotations):
        for obj in objects:
            x, y, w, h = (int(v) for v in obj.box)
            prefix = f"{t + 1},{obj.id},{x + 1},{y + 1},{w},{h}"
            if benchmark in TARGETS_ONLY_BENCHMARKS:
                if obj.role is ObjectRole.PEDESTRIAN:
                    rows.append((obj.id, t, f"{prefix},1,1,1"))
            elif benchmark in CLASS_COLUMN_BENCHMARKS:
                flag_class = MOT_CLASSES.get(obj.role)
                if flag_class is None:
                    continue
                visibility = float(round(obj.visibility, 5))
                rows.append((obj.id, t, f"{prefix},{flag_class[0]},{flag_class[1]},{visibility}"))
            elif obj.role in MOT15_ROLES:
                rows.append((obj.id, t, f"{prefix},1,-1,-1,-1"))
    if benchmark in CLASS_COLUMN_BENCHMARKS:
        rows.sort(key=lambda r: (r[0], r[1]))  # by id, then frame (official order)
    else:
        rows.sort(key=lambda r: (r[1], r[0]))  # by frame (as 2DMOT2015 files are)
    return [line for _, _, line in rows]


def _det_lines(benchmark: str, detections: Detections) -> list[str]:
    scale = MOT15_SCORE_SCALE if benchmark == "MOT15" else 1.0
    digits = 3 if benchmark == "MOT15" else 5
    lines = []
    for t, (x, y, w, h), score in zip(
        detections.frames, detections.boxes, detections.scores, strict=True
    ):
        box = f"{x + 1:.2f},{y + 1:.2f},{w:.2f},{h:.2f}"
        lines.append(f"{t + 1},-1,{box},{score * scale:.{digits}f},-1,-1,-1")
    return lines


def _write_lines(path: Path, lines: list[str]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("".join(line + "\n" for line in lines), encoding="ascii")


def write_motchallenge(
    root: str | Path, benchmark: str, *, spec: MotChallengeSpec = DEFAULT_SPEC
) -> None:
    """Render ``spec`` and write it under ``root`` in ``benchmark``'s MOTChallenge layout.

    ``benchmark`` (one of :data:`BENCHMARKS`) decides the gt.txt columns and the score range.
    Equal specs give byte-identical text files and identical frames; files are overwritten.
    """
    if benchmark not in BENCHMARKS:
        raise ValueError(
            f"unknown MOTChallenge benchmark {benchmark!r}; valid: {', '.join(BENCHMARKS)}"
        )
    root = Path(root)
    jpeg_params = [cv2.IMWRITE_JPEG_QUALITY, int(spec.jpeg_quality)]
    for seq in spec.sequences:
        write_sequence(root / seq.split / seq.name, seq, render_scene(seq.scene), benchmark,
                       spec.detection_noise, jpeg_params)


def write_sequence(
    seq_dir: Path, seq: SequenceSpec, frames: Iterable[SyntheticFrame], benchmark: str,
    noise: DetectionNoise, jpeg_params: list[int], *, frame_digits: int = 6,
    det_path: Path | None = None,
) -> None:
    """Write one sequence's frames, ``seqinfo.ini``, ground truth and detections.

    Frames are ``img1/<frame>.jpg`` with ``frame_digits`` digits; detections go to
    ``det_path`` (default: the public ``det/det.txt``).
    """
    image_dir = seq_dir / "img1"
    image_dir.mkdir(parents=True, exist_ok=True)
    annotations: list[tuple[ObjectAnnotation, ...]] = []
    for frame in frames:
        path = image_dir / f"{frame.index + 1:0{frame_digits}d}.jpg"
        if not cv2.imwrite(str(path), frame.image[:, :, ::-1], jpeg_params):
            raise OSError(f"{path}: cv2.imwrite failed to write the JPEG frame")
        annotations.append(frame.objects)
    (seq_dir / "seqinfo.ini").write_text(_seqinfo_text(seq), encoding="ascii")
    if seq.split in SPLITS_WITH_GROUND_TRUTH:
        _write_lines(seq_dir / "gt" / "gt.txt", _gt_lines(benchmark, annotations))
    detections = simulate_detections(
        annotations,
        (seq.scene.width, seq.scene.height),
        noise,
        np.random.default_rng([seq.scene.seed, _STREAM_DETECTIONS]),
    )
    _write_lines(det_path or seq_dir / "det" / "det.txt", _det_lines(benchmark, detections))
