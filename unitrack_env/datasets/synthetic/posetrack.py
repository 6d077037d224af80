"""Synthetic PoseTrack 2018 data set (multi-person pose tracking), in the release's layout.

:func:`write_posetrack` writes ``posetrack_data/annotations/{train,val}/<seq>.json``,
``posetrack_data/images/{train,val,test}/<seq>/*.jpg`` and simulated pose detections in
``detections/{train,val,test}/<seq>.json``. As in the release, a walking person is
annotated with its visible joints only (others ``(0, 0, 0)``), its head box (the PCKh
reference) and a 0-based ``track_id``, and a standing person only by an ignore region, as
PoseTrack treats unannotated crowds. :func:`simulate_pose_detections` stands in for the pose
estimator; its output order is shuffled, since a detector's order says nothing of ids.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from unitrack_env.datasets.posetrack_json import image_id, write_posetrack_json
from unitrack_env.datasets.posetrack_records import (
    DATA_FOLDER,
    NUM_KEYPOINTS,
    PERSON_CATEGORY,
    PERSONS_PER_IMAGE,
    PoseTrackImage,
    PoseTrackPerson,
    PoseTrackVideo,
)
from unitrack_env.datasets.synthetic.poses import (
    POSETRACK_FROM_SKELETON,
    head_box,
    joint_visibility,
    select_joints,
    skeleton_pixels,
)
from unitrack_env.datasets.synthetic.scene import SyntheticVideo, render_scene
from unitrack_env.datasets.synthetic.scene_model import ObjectAnnotation, ObjectRole, SceneConfig

#: Benchmarks (cache names) this writer produces.
BENCHMARKS = ("PoseTrack2018",)
#: Sub-folder of the data set root holding the simulated detections.
DETECTIONS_FOLDER = "detections"
#: A frame is labelled when its index is a multiple of this ...
LABEL_EVERY = 4
#: ... or when it lies in a dense block of this many frames in the middle of the video.
DENSE_LABELED_FRAMES = 16
#: Splits that ship annotation files.
ANNOTATED_SPLITS = frozenset({"train", "val"})
#: Ignore regions enlarge a standing person's box by this fraction on every side.
IGNORE_MARGIN = 0.1
#: Seed-stream index of the detection noise (the scene uses 0 and 1).
_STREAM_DETECTIONS = 2


@dataclass(frozen=True)
class PoseDetectionNoise:
    """How the simulated pose estimator deviates from the ground truth.

    A person with visibility ``v`` is missed with probability
    ``min(1, miss_rate + occlusion_miss_weight * (1 - v) ** 2)``. A visible joint is found with
    probability ``joint_recall``, jittered by ``joint_jitter`` x height; an occluded joint in the
    image is hallucinated with ``occluded_joint_rate`` (``occluded_jitter``). Joint scores are
    uniform in ``visible_score`` / ``occluded_score``; the pose score is their mean. Standing
    people are detected with ``static_person_rate``; random poses arrive Poisson
    (``false_poses_per_frame``); poses with under ``min_joints`` joints are dropped.
    """

    miss_rate: float = 0.03
    occlusion_miss_weight: float = 0.9
    joint_recall: float = 0.95
    joint_jitter: float = 0.012
    occluded_joint_rate: float = 0.3
    occluded_jitter: float = 0.04
    visible_score: tuple[float, float] = (0.55, 0.98)
    occluded_score: tuple[float, float] = (0.05, 0.45)
    static_person_rate: float = 0.7
    false_poses_per_frame: float = 0.1
    false_pose_height: tuple[float, float] = (60.0, 120.0)
    min_joints: int = 3


@dataclass(frozen=True)
class SequenceSpec:
    """One synthetic PoseTrack video (``split``: ``train``/``val`` annotated, ``test`` not)."""

    name: str
    split: str
    scene: SceneConfig

    def __post_init__(self) -> None:
        if self.split not in ("train", "val", "test"):
            raise ValueError(f"SequenceSpec.split={self.split!r}: use train, val or test")
        head = self.name.split("_", 1)[0]
        if not (head.isdigit() and len(head) == 6):
            raise ValueError(f"SequenceSpec.name={self.name!r}: must start with a 6-digit id")

    @property
    def video_number(self) -> int:
        """The numeric video id."""
        return int(self.name.split("_", 1)[0])


@dataclass(frozen=True)
class PoseTrackSpec:
    """A synthetic PoseTrack data set."""

    sequences: tuple[SequenceSpec, ...]
    detection_noise: PoseDetectionNoise = field(default_factory=PoseDetectionNoise)
    jpeg_quality: int = 90


def _scene(seed: int, width: int = 640, height: int = 360, frames: int = 48,
           objects: int = 6) -> SceneConfig:
    return SceneConfig(width=width, height=height, num_frames=frames, num_objects=objects,
                       num_crossings=2, num_static_persons=1, num_occluders=1, seed=seed)


#: The embedded default: one train, two val (one of another size) and one test video,
#: each with two forced crossings, a standing person (ignore region) and an occluder.
DEFAULT_SPEC = PoseTrackSpec(sequences=(
    SequenceSpec("900001_synthetic_train", "train", _scene(41)),
    SequenceSpec("900002_synthetic_val", "val", _scene(42, frames=56)),
    SequenceSpec("900003_synthetic_val", "val", _scene(43, 576, 324, 48, 5)),
    SequenceSpec("900004_synthetic_test", "test", _scene(44, frames=40)),
))


def annotated_frames(benchmark: str = "PoseTrack2018", split: str | None = None,
                     spec: PoseTrackSpec = DEFAULT_SPEC) -> dict[str, int]:
    """Frames of each video of ``split`` (None: any) that has an annotation file.

    Known without writing anything, e.g. to plan work on data not generated yet.
    """
    return {s.name: s.scene.num_frames for s in spec.sequences
            if s.split in ANNOTATED_SPLITS and split in (None, s.split)}


def labeled_frames(num_frames: int) -> np.ndarray:
    """Return the ``(num_frames,)`` bool mask of annotated frames."""
    index = np.arange(num_frames)
    start = max(0, (num_frames - DENSE_LABELED_FRAMES) // 2)
    return (index % LABEL_EVERY == 0) | ((index >= start) & (index < start + DENSE_LABELED_FRAMES))


def person_keypoints(video: SyntheticVideo, obj_id: int, t: int,
                     instance_map: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One person's ``(xy (17, 2), inside (17,), visible (17,))`` at ``t`` (ears never inside)."""
    obj = video.object(obj_id)
    xy = select_joints(skeleton_pixels(obj, t), POSETRACK_FROM_SKELETON)
    inside, visible = joint_visibility(xy, instance_map, obj_id)
    return xy, inside, visible


def _round(values: np.ndarray) -> np.ndarray:
    return np.round(values, 2)


def _ignore_polygon(box: tuple[float, float, float, float], width: int, height: int
                    ) -> np.ndarray:
    x, y, w, h = box
    x0 = max(0.0, x - IGNORE_MARGIN * w)
    y0 = max(0.0, y - IGNORE_MARGIN * h)
    x1 = min(width - 1.0, x + w + IGNORE_MARGIN * w)
    y1 = min(height - 1.0, y + h + IGNORE_MARGIN * h)
    return np.round(np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]), 1)


def _ground_truth_people(video: SyntheticVideo, t: int, objects: tuple[ObjectAnnotation, ...],
                         instance_map: np.ndarray, iid: int) -> list[PoseTrackPerson]:
    people = []
    for obj in objects:
        if obj.role is not ObjectRole.PEDESTRIAN:
            continue
        xy, _, visible = person_keypoints(video, obj.id, t, instance_map)
        if not visible.any():
            continue
        keypoints = np.zeros((NUM_KEYPOINTS, 3))
        keypoints[visible, :2] = _round(xy[visible])
        keypoints[visible, 2] = 1.0
        people.append(PoseTrackPerson(
            image_id=iid, keypoints=keypoints, track_id=obj.id - 1, scores=np.zeros(0),
            bbox=tuple(float(v) for v in obj.box),  # type: ignore[arg-type]
            bbox_head=tuple(float(v) for v in _round(np.array(
                head_box(video.object(obj.id), t)))),  # type: ignore[arg-type]
            id=iid * PERSONS_PER_IMAGE + len(people),
            extra={"category_id": 1, "iscrowd": False, "num_keypoints": int(visible.sum())},
        ))
    return people


def simulate_pose_detections(
    video: SyntheticVideo,
    t: int,
    objects: tuple[ObjectAnnotation, ...],
    instance_map: np.ndarray,
    iid: int,
    noise: PoseDetectionNoise,
    rng: np.random.Generator,
) -> list[PoseTrackPerson]:
    """Simulate a pose estimator's output on frame ``t`` (see :class:`PoseDetectionNoise`)."""
    height_px, width_px = instance_map.shape
    out: list[PoseTrackPerson] = []

    def emit(xy: np.ndarray, found: np.ndarray, scores: np.ndarray) -> None:
        if found.sum() < noise.min_joints:
            return
        keypoints = np.zeros((NUM_KEYPOINTS, 3))
        keypoints[found, :2] = _round(xy[found])
        keypoints[found, 2] = 1.0
        joint_scores = np.where(found, np.round(scores, 4), 0.0)
        out.append(PoseTrackPerson(
            image_id=iid, keypoints=keypoints, scores=joint_scores,
            score=float(np.round(joint_scores[found].mean(), 4)),
            extra={"category_id": 1},
        ))

    for obj in objects:
        if obj.role is ObjectRole.OCCLUDER:
            continue
        draws = rng.uniform(size=(4, NUM_KEYPOINTS))  # always drawn: keeps the stream aligned
        jitter = rng.standard_normal((NUM_KEYPOINTS, 2))
        gate = rng.uniform()
        if obj.role is ObjectRole.STATIC_PERSON:
            if gate >= noise.static_person_rate:
                continue
        elif gate < noise.miss_rate + noise.occlusion_miss_weight * (1.0 - obj.visibility) ** 2:
            continue
        xy, inside, visible = person_keypoints(video, obj.id, t, instance_map)
        occluded = inside & ~visible
        found = (visible & (draws[0] < noise.joint_recall)) | (
            occluded & (draws[1] < noise.occluded_joint_rate))
        sigma = np.where(visible, noise.joint_jitter, noise.occluded_jitter) * obj.box[3]
        noisy = np.nan_to_num(xy) + jitter * sigma[:, None]
        lo_v, hi_v = noise.visible_score
        lo_o, hi_o = noise.occluded_score
        scores = np.where(visible, lo_v + (hi_v - lo_v) * draws[2], lo_o + (hi_o - lo_o) * draws[3])
        emit(noisy, found, scores)
    for _ in range(rng.poisson(noise.false_poses_per_frame)):
        h = rng.uniform(*noise.false_pose_height)
        cx, cy = rng.uniform(0, width_px), rng.uniform(0, height_px)
        xy = np.column_stack([cx + rng.uniform(-0.2, 0.2, NUM_KEYPOINTS) * h,
                              cy + rng.uniform(-0.5, 0.5, NUM_KEYPOINTS) * h])
        found = rng.uniform(size=NUM_KEYPOINTS) < 0.6
        found[3:5] = False
        emit(xy, found, rng.uniform(0.05, 0.5, NUM_KEYPOINTS))
    order = rng.permutation(len(out))  # a detector's output order says nothing about ids
    return [replace(out[i], id=iid * PERSONS_PER_IMAGE + n) for n, i in enumerate(order)]


def write_posetrack(root: str | Path, benchmark: str = "PoseTrack2018", *,
                    spec: PoseTrackSpec = DEFAULT_SPEC) -> None:
    """Render ``spec`` under ``root`` in the PoseTrack 2018 layout (``benchmark``: its name)."""
    if benchmark not in BENCHMARKS:
        raise ValueError(f"write_posetrack writes {BENCHMARKS}, not {benchmark!r}")
    root = Path(root)
    data = root / DATA_FOLDER
    jpeg = [cv2.IMWRITE_JPEG_QUALITY, int(spec.jpeg_quality)]
    for seq in spec.sequences:
        image_dir = data / "images" / seq.split / seq.name
        image_dir.mkdir(parents=True, exist_ok=True)
        video = render_scene(seq.scene)
        labeled = labeled_frames(video.num_frames)
        rng = np.random.default_rng([seq.scene.seed, _STREAM_DETECTIONS])
        images: list[PoseTrackImage] = []
        truth: list[list[PoseTrackPerson]] = []
        detections: list[list[PoseTrackPerson]] = []
        for frame in video:
            t = frame.index
            path = image_dir / f"{t:06d}.jpg"
            if not cv2.imwrite(str(path), frame.image[:, :, ::-1], jpeg):
                raise OSError(f"{path}: cv2.imwrite failed to write the JPEG frame")
            iid = image_id(seq.video_number, t)
            regions = tuple(_ignore_polygon(o.box, video.width, video.height)
                            for o in frame.objects if o.role is ObjectRole.STATIC_PERSON)
            images.append(PoseTrackImage(
                id=iid, file_name=f"images/{seq.split}/{seq.name}/{t:06d}.jpg",
                is_labeled=bool(labeled[t]), nframes=video.num_frames, frame_id=iid,
                vid_id=f"{seq.video_number:06d}",
                ignore_regions=regions if labeled[t] else (),
                extra={"has_no_densepose": True, "width": video.width, "height": video.height},
            ))
            truth.append(_ground_truth_people(video, t, frame.objects, frame.instance_map, iid)
                         if labeled[t] else [])
            detections.append(simulate_pose_detections(
                video, t, frame.objects, frame.instance_map, iid, spec.detection_noise, rng))
        category = [dict(PERSON_CATEGORY)]
        if seq.split in ANNOTATED_SPLITS:
            write_posetrack_json(data / "annotations" / seq.split / f"{seq.name}.json",
                                 PoseTrackVideo(images, truth, category))
        else:  # a test split's detection file must not reveal which frames are labelled
            images = [replace(im, is_labeled=False, ignore_regions=()) for im in images]
        write_posetrack_json(root / DETECTIONS_FOLDER / seq.split / f"{seq.name}.json",
                             PoseTrackVideo(images, detections, category))
