"""Readers and writers of the MOTS formats: MOTS Challenge (MOTS20) and KITTI MOTS.

Format (Voigtlaender et al., "MOTS", CVPR 2019; restated in TrackEval's
``docs/MOTS-format.txt``): a **txt** file has one line per object and frame,
``time_frame id class_id img_height img_width rle``, space-separated, ``rle`` being a COCO
compressed run-length encoding (``pycocotools.mask``) of the mask; a **png** instance map
(``instances/<seq>/<frame>.png``) is one 16-bit image per frame whose pixels are the ids.
Ids are ``class_id * 1000 + instance`` (class 1 car, 2 pedestrian); id 10000 (class 10) is an
ignore region, 0 the background. Masks of one frame never overlap (TrackEval rejects
overlapping ground truth and results). Frames are numbered as TrackEval reads them: MOTS20
from 1 (``MOTSChallenge``, ``{gt_folder}/{seq}/gt/gt.txt``), KITTI MOTS from 0
(``KittiMOTS``). The on-disk layouts and detection files are in docs/envs/mots.md; neither
benchmark ships mask detections, so ``"public"`` is where the embedded synthetic data put
theirs.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from unitrack_env.datasets.limits import MAX_TRACKS, check_track_count
from unitrack_env.datasets.motchallenge import read_seqinfo
from unitrack_env.datasets.motchallenge_tables import MAX_GT_ID
from unitrack_env.datasets.mots_format import (
    IGNORE_ID,
    MaskAnnotations,
    parse_instances_txt,
    read_instances_png,
)
from unitrack_env.datasets.rle import mask_api as mask_utils
from unitrack_env.datasets.sot import read_image_size
from unitrack_env.errors import DataFormatError

__all__ = [
    "BENCHMARKS",
    "KITTI_FRAME_RATE",
    "KITTI_SPLITS",
    "MOTSDataset",
    "MOTSSequenceInfo",
    "check_ground_truth",
]

#: Benchmarks (layouts) read by :class:`MOTSDataset`.
BENCHMARKS = ("MOTS20", "KITTI-MOTS")
#: KITTI MOTS frame rate (KITTI's cameras run at 10 Hz).
KITTI_FRAME_RATE = 10.0
#: Splits of the KITTI tracking image folders.
KITTI_SPLITS = ("training", "testing")


@dataclass(frozen=True)
class MOTSSequenceInfo:
    """Where a sequence's frames are and how they are numbered (first: MOTS20 1, KITTI 0)."""

    name: str
    image_dir: Path
    length: int
    first_frame: int
    width: int
    height: int
    frame_rate: float
    image_ext: str

    def frame_path(self, frame: int) -> Path:
        """Image file of a frame number (file numbering)."""
        return self.image_dir / f"{frame:06d}{self.image_ext}"


class MOTSDataset:
    """A MOTS data set on disk in the MOTS20 or the KITTI MOTS layout (docs/envs/mots.md).

    ``split``: MOTS20 ``"train"``/``"test"``, KITTI ``"training"``/``"testing"``;
    ``detections``: ``"public"``, ``"gt"`` or a folder of ``<seq>.txt`` files.
    """

    def __init__(self, root: str | os.PathLike, benchmark: str = "MOTS20", split: str = "train",
                 detections: str | os.PathLike = "public") -> None:
        if benchmark not in BENCHMARKS:
            raise ValueError(
                f"unknown MOTS benchmark {benchmark!r}; valid: {', '.join(BENCHMARKS)}")
        self.root = Path(root)
        self.benchmark = benchmark
        self.split = split
        self.detections = detections
        if benchmark == "MOTS20":
            self.split_dir = self.root / split
        else:
            if split not in KITTI_SPLITS:
                raise ValueError(f"KITTI MOTS split must be one of {KITTI_SPLITS}, got {split!r}")
            self.split_dir = self.root / split / "image_02"
        if not self.split_dir.is_dir():
            raise DataFormatError(self.split_dir, f"{benchmark} split folder not found")
        self.sequence_names = sorted(p.name for p in self.split_dir.iterdir() if p.is_dir())
        if not self.sequence_names:
            raise DataFormatError(self.split_dir, "contains no sequence folders")

    # -------------------------------------------------------------- paths
    def gt_path(self, name: str) -> Path:
        """The ground-truth file (txt) or folder (png) of a sequence (it may not exist)."""
        if self.benchmark == "MOTS20":
            return self.split_dir / name / "gt" / "gt.txt"
        txt = self.root / "instances_txt" / f"{name}.txt"
        png = self.root / "instances" / name
        return txt if txt.is_file() or not png.is_dir() else png

    def detection_path(self, name: str) -> Path:
        """The detection file of a sequence (for ``detections != "gt"``)."""
        if str(self.detections) == "public":
            if self.benchmark == "MOTS20":
                return self.split_dir / name / "det" / "det.txt"
            return self.root / self.split / "det_02" / f"{name}.txt"
        return Path(self.detections) / f"{name}.txt"

    def has_ground_truth(self, name: str) -> bool:
        """Whether the sequence has ground truth (txt file or png folder)."""
        path = self.gt_path(name)
        return path.is_file() or path.is_dir()

    # -------------------------------------------------------------- reading
    def info(self, name: str) -> MOTSSequenceInfo:
        """The sequence's frame layout (cheap: seqinfo.ini or one directory listing)."""
        if name not in self.sequence_names:
            raise KeyError(f"no sequence {name!r} in {self.split_dir}")
        if self.benchmark == "MOTS20":
            seq = read_seqinfo(self.split_dir / name)
            return MOTSSequenceInfo(name, seq.path / seq.image_dir, seq.length, 1, seq.width,
                                    seq.height, seq.frame_rate, seq.image_ext)
        folder = self.split_dir / name
        files = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".png", ".jpg"))
        if not files:
            raise DataFormatError(folder, "contains no frames (000000.png ...)")
        width, height = read_image_size(files[0])
        return MOTSSequenceInfo(name, folder, len(files), int(files[0].stem), width, height,
                                KITTI_FRAME_RATE, files[0].suffix)

    def ground_truth(self, name: str) -> MaskAnnotations | None:
        """The sequence's ground truth, or None on a split without it."""
        if not self.has_ground_truth(name):
            return None
        path = self.gt_path(name)
        gt = read_instances_png(path) if path.is_dir() else parse_instances_txt(
            path, max_ids=MAX_TRACKS)
        check_ground_truth(gt, self.info(name))
        return gt

    def load_detections(self, name: str, class_id: int) -> MaskAnnotations:
        """The sequence's detections of class ``class_id`` (DataFormatError if missing)."""
        if str(self.detections) == "gt":
            gt = self.ground_truth(name)
            if gt is None:
                raise DataFormatError(self.gt_path(name), "detections='gt' needs ground truth, "
                                      "which this split does not have")
            keep = gt.classes == class_id
            return gt.select(keep)
        path = self.detection_path(name)
        if not path.is_file():
            raise DataFormatError(path, "detection file not found; MOTS benchmarks ship no "
                                  "public mask detections: pass detections=<folder of <seq>.txt> "
                                  "or detections='gt'")
        dets = parse_instances_txt(path, allow_score=True)
        return dets.select(dets.classes == class_id)


def _check_ids(gt: MaskAnnotations) -> None:
    """Refuse ground-truth ids outside ``0..MAX_GT_ID`` or more than ``MAX_TRACKS`` of them.

    TrackEval allocates an array over the id range and matrices over the id count.
    """
    if not len(gt):
        return
    bad = (gt.ids < 0) | (gt.ids > MAX_GT_ID)
    if bad.any():
        i = int(np.argmax(bad))
        raise gt._error(i, f"id {gt.ids[i]} is outside 0..{MAX_GT_ID}: TrackEval indexes an "
                           "array by ground-truth id (a huge one exhausts memory); renumber "
                           "the ids", "id")
    check_track_count(gt.ids, gt.source or Path("<memory>"), field="id")


def check_ground_truth(gt: MaskAnnotations, info: MOTSSequenceInfo) -> None:
    """Refuse ground truth that TrackEval would refuse when scoring, naming file and line.

    Frames in range, masks of the frame's size, no id twice in a frame (except the ignore id
    10000, which TrackEval merges), no overlapping masks; checked on the RLEs, undecoded.
    """
    last = info.first_frame + info.length - 1
    _check_ids(gt)
    for i in range(len(gt)):
        if not info.first_frame <= gt.frames[i] <= last:
            raise gt._error(i, f"time_frame {gt.frames[i]} is not a frame of the sequence "
                               f"({info.first_frame}..{last})", "time_frame")
        if (gt.heights[i], gt.widths[i]) != (info.height, info.width):
            raise gt._error(i, f"mask is {gt.widths[i]}x{gt.heights[i]} but the frames are "
                               f"{info.width}x{info.height}", "img_height")
    for frame in np.unique(gt.frames):
        idx = gt.rows(frame)
        ids = gt.ids[idx][gt.ids[idx] != IGNORE_ID]  # an ignore region may span several rows
        if len(np.unique(ids)) != len(ids):
            seen: set[int] = set()
            for i in idx:
                if int(gt.ids[i]) in seen and gt.ids[i] != IGNORE_ID:
                    raise gt._error(int(i), f"id {gt.ids[i]} appears twice in frame {frame}",
                                    "id")
                seen.add(int(gt.ids[i]))
        rles = gt.rles(idx)
        if len(rles) < 2:
            continue
        union = mask_utils.area(mask_utils.merge(rles, intersect=False))
        if int(union) != int(mask_utils.area(rles).sum()):
            merged = rles[0]
            for k in range(1, len(rles)):
                if mask_utils.area(mask_utils.merge([merged, rles[k]], intersect=True)) > 0:
                    raise gt._error(
                        int(idx[k]), f"mask of id {gt.ids[idx[k]]} overlaps another mask of frame "
                                     f"{frame}; MOTS masks of one frame must be disjoint "
                                     "(TrackEval refuses overlapping masks)", "rle")
                merged = mask_utils.merge([merged, rles[k]], intersect=False)
