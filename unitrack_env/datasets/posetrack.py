"""Reader and writer of PoseTrack 2018 JSON (ground truth, results and pose detections).

Reads the release layout: ``posetrack_data/annotations/{train,val}/<sequence>.json`` and
``posetrack_data/images/{train,val,test}/<sequence>/*.jpg``. A sequence file is COCO-like
(field meanings from poseval's ``convert.py``, leonid-pishchulin/poseval): ``images`` has one
entry per frame, ``annotations`` one per person and labelled frame (``track_id`` 0-based per
video, 17 ``(x, y, v)`` keypoints in COCO order), ``categories`` one ``person`` whose
``head_bottom``/``head_top`` sit in COCO's eye slots (the ear slots are never annotated).
Results and pose detections use the same schema (docs/envs/posetrack.md). Keypoints are
floating-point pixels, kept exactly as written.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path

from unitrack_env.datasets.posetrack_json import image_id, read_posetrack_json, video_number
from unitrack_env.datasets.posetrack_records import (
    DATA_FOLDER,
    IMAGE_ID_BASE,
    SPLITS,
    PoseTrackImage,
    PoseTrackVideo,
)
from unitrack_env.datasets.sot import read_image_size
from unitrack_env.errors import DataFormatError, UnknownSequenceError
from unitrack_env.io import path_inside

__all__ = ["PoseTrackDataset", "PoseTrackSequence", "images_from_files", "locate_data_folder"]


@dataclass(frozen=True)
class PoseTrackSequence:
    """One video of a split (``images`` made up from the files for splits without annotations)."""

    name: str
    split: str
    images: tuple[PoseTrackImage, ...]
    frame_paths: tuple[Path, ...]
    ground_truth: PoseTrackVideo | None
    image_size: tuple[int, int]
    annotation_path: Path | None

    @property
    def length(self) -> int:
        """Number of frames (steps)."""
        return len(self.images)


def locate_data_folder(root: str | os.PathLike) -> Path:
    """Return the ``posetrack_data`` folder given it or the folder that holds it."""
    root = Path(root)
    if (root / DATA_FOLDER).is_dir():
        return root / DATA_FOLDER
    if (root / "images").is_dir() or (root / "annotations").is_dir():
        return root
    raise DataFormatError(root, f"neither holds '{DATA_FOLDER}/' nor is one (expected "
                                "annotations/<split>/*.json and images/<split>/<sequence>/)")


def images_from_files(sequence: str, split: str, paths: list[Path]) -> tuple[PoseTrackImage, ...]:
    """Make ``images`` entries for frame files that have no annotation file (test split).

    Ids follow the release's scheme (:func:`image_id`) when the sequence name starts with a
    numeric video id, else they count from :data:`IMAGE_ID_BASE`.
    """
    number = video_number(sequence)
    out = []
    for path in paths:
        index = int(path.stem)
        iid = image_id(number, index) if number is not None else IMAGE_ID_BASE + index
        out.append(PoseTrackImage(
            id=iid, file_name=f"images/{split}/{sequence}/{path.name}", is_labeled=False,
            nframes=len(paths), frame_id=iid,
            vid_id=f"{number:06d}" if number is not None else sequence,
        ))
    return tuple(out)


class PoseTrackDataset:
    """The sequences of one split of a PoseTrack 2018 folder (test: its image folders)."""

    def __init__(self, root: str | os.PathLike, split: str = "val") -> None:
        if split not in SPLITS:
            raise ValueError(f"split must be one of {SPLITS}; got {split!r}")
        self.data_dir = locate_data_folder(root)
        self.split = split
        self.annotation_dir = self.data_dir / "annotations" / split
        self.image_dir = self.data_dir / "images" / split
        files = sorted(self.annotation_dir.glob("*.json")) if self.annotation_dir.is_dir() else []
        if files:
            self.sequence_names = [p.stem for p in files]
            self.annotated = True
        elif self.image_dir.is_dir():
            self.sequence_names = sorted(p.name for p in self.image_dir.iterdir() if p.is_dir())
            self.annotated = False
        else:
            self.sequence_names = []
            self.annotated = False
        if not self.sequence_names:
            raise DataFormatError(
                self.data_dir, f"no sequences for split '{split}' (looked for "
                               f"annotations/{split}/*.json and images/{split}/<sequence>/)")

    def has_ground_truth(self, name: str) -> bool:
        """Whether ``name`` has an annotation file."""
        return (self.annotation_dir / f"{name}.json").is_file()

    def _check(self, name: str) -> None:
        if name not in self.sequence_names:
            raise UnknownSequenceError(
                f"no PoseTrack sequence '{name}' in {self.data_dir} ({self.split}); "
                f"available: {', '.join(self.sequence_names)}")

    def sequence_length(self, name: str) -> int:
        """Number of frames of ``name`` (its ``images`` entries, or its image files)."""
        self._check(name)
        if self.has_ground_truth(name):
            return len(read_posetrack_json(self.annotation_dir / f"{name}.json").images)
        return len(self._image_files(name))

    def _image_files(self, name: str) -> list[Path]:
        folder = self.image_dir / name
        if not folder.is_dir():
            raise DataFormatError(folder, f"frames of '{name}' missing")
        files = sorted(p for p in folder.iterdir()
                       if p.suffix.lower() in (".jpg", ".jpeg", ".png") and p.stem.isdigit())
        if not files:
            raise DataFormatError(folder, "holds no '<frame>.jpg' images")
        return files

    def load(self, name: str) -> PoseTrackSequence:
        """Read one sequence: its frame entries, frame files (each must exist) and ground truth."""
        self._check(name)
        annotation = self.annotation_dir / f"{name}.json"
        if annotation.is_file():
            video = read_posetrack_json(annotation)
            images = tuple(video.images)
            paths = tuple(self._frame_path(annotation, name, image, k)
                          for k, image in enumerate(images))
            _warn_other_video(annotation, name, paths, self.image_dir / name)
        else:
            video, annotation = None, None
            files = self._image_files(name)
            images = images_from_files(name, self.split, files)
            paths = tuple(files)
        if not images:
            raise DataFormatError(annotation or self.image_dir / name, "has no frames")
        first = images[0]
        if "width" in first.extra and "height" in first.extra:
            size = (int(first.extra["width"]), int(first.extra["height"]))
        else:
            size = read_image_size(paths[0])
        return PoseTrackSequence(name, self.split, images, paths, video, size, annotation)

    def _frame_path(self, annotation: Path, name: str, image: PoseTrackImage, k: int) -> Path:
        path = path_inside(self.data_dir, image.file_name, annotation,
                           field=f"images[{k}].file_name")
        if path.is_file():
            return path
        fallback = self.image_dir / name / Path(image.file_name).name
        if fallback.is_file():
            return fallback
        raise DataFormatError(annotation, f"lists frame {image.file_name!r} but neither {path} "
                                          f"nor {fallback} exists", field="images.file_name")


def _warn_other_video(annotation: Path, name: str, paths: tuple[Path, ...], own: Path) -> None:
    """Warn when ``images.file_name`` leads into another video's folder while ``own`` exists.

    The frames are played from where ``file_name`` points (the PoseTrack tools read it so),
    but a copied or renamed annotation file shows one video's frames against another's
    ground truth, and the scorer cannot notice.
    """
    others = sorted({path.parent.name for path in paths} - {name})
    if others and own.is_dir():
        warnings.warn(
            f"{annotation}: images.file_name leads into the folder(s) {others} of another "
            f"video, not into this sequence's own {own}; those frames are played. A copied or "
            f"renamed annotation file? Point file_name at images/<split>/{name}/",
            stacklevel=3)
