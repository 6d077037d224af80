"""Reader and result writer for DAVIS-2017 semi-supervised video object segmentation.

Reads ``JPEGImages/480p/<seq>/*.jpg``, ``Annotations/480p/<seq>/*.png`` (palette PNGs;
test-dev: first frame only) and ``ImageSets/2017/<split>.txt``. A palette PNG's *indices* are
the labels, which OpenCV cannot return (``cv2.IMREAD_UNCHANGED`` expands the palette to BGR,
checked on the fixture), so PNGs are read and written with Pillow. A sequence's objects are
the labels of its first annotation other than 0 and 255: DAVIS-2017 labels are ``1..n``, so
this equals the official evaluation's ``1..max``.
"""

from __future__ import annotations

import io
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from unitrack_env.datasets.base import SequenceDataset
from unitrack_env.datasets.limits import check_image_header
from unitrack_env.datasets.sot import read_image_size
from unitrack_env.errors import DataFormatError, UnknownSequenceError
from unitrack_env.io import atomic_write_bytes, path_inside

DAVIS_VOID_LABEL: int = 255
"""Annotation label of void pixels."""

DAVIS_RESOLUTIONS: tuple[str, ...] = ("480p", "Full-Resolution")
"""Resolution folders of the DAVIS release."""

PALETTE_SIZE: int = 256
"""Entries in a PNG palette."""


def voc_palette(size: int = PALETTE_SIZE) -> np.ndarray:
    """Return the ``(size, 3)`` PASCAL VOC colour map, DAVIS's annotation palette.

    >>> voc_palette(5).tolist()
    [[0, 0, 0], [128, 0, 0], [0, 128, 0], [128, 128, 0], [0, 0, 128]]
    """
    index = np.arange(size)
    colours = np.zeros((size, 3), dtype=np.int64)
    for bit in range(8):
        for channel in range(3):
            colours[:, channel] |= ((index >> (3 * bit + channel)) & 1) << (7 - bit)
    return colours.astype(np.uint8)


DAVIS_PALETTE: np.ndarray = voc_palette()
"""The 256-entry DAVIS annotation palette, ``(256, 3)`` uint8 (read-only)."""
DAVIS_PALETTE.setflags(write=False)


def _pil_image() -> Any:
    try:
        # lazy: start-up cost (PIL)
        from PIL import Image
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise ImportError(
            "reading and writing DAVIS palette PNGs needs Pillow: pip install pillow"
        ) from err
    return Image


def read_label_png(path: str | Path) -> np.ndarray:
    """Read a ``(H, W)`` uint8 label map (palette indices) from a "P" or "L" PNG.

    RGB or 16-bit images whose pixels are not labels raise DataFormatError.
    """
    image_mod = _pil_image()
    check_image_header(path)  # a decompression bomb is refused before Pillow opens it
    try:
        with warnings.catch_warnings():  # Pillow's bomb warning is an error here, not a note
            warnings.simplefilter("error", image_mod.DecompressionBombWarning)
            image = image_mod.open(path)
        with image:
            mode = image.mode
            if mode not in ("P", "L"):
                raise DataFormatError(
                    path,
                    f"PNG mode {mode!r} is not a label map; DAVIS annotations and results must "
                    "be palette ('P') PNGs whose indices are object ids",
                )
            return np.array(image, dtype=np.uint8)
    except (image_mod.DecompressionBombError, image_mod.DecompressionBombWarning) as err:
        raise DataFormatError(path, f"image too large to decode ({err})") from None
    except OSError as err:
        raise DataFormatError(path, f"missing or unreadable PNG ({err})") from err


def read_png_palette(path: str | Path) -> np.ndarray:
    """Return the palette of a palette PNG as ``(n, 3)`` uint8 (n = entries stored)."""
    image_mod = _pil_image()
    check_image_header(path)
    try:
        with image_mod.open(path) as image:
            palette = image.getpalette()
    except (image_mod.DecompressionBombError, image_mod.DecompressionBombWarning) as err:
        raise DataFormatError(path, f"image too large to decode ({err})") from None
    except OSError as err:
        raise DataFormatError(path, f"missing or unreadable PNG ({err})") from err
    if palette is None:
        raise DataFormatError(path, "PNG has no palette")
    return np.asarray(palette, dtype=np.uint8).reshape(-1, 3)


def write_label_png(
    path: str | Path, labels: np.ndarray, palette: np.ndarray = DAVIS_PALETTE
) -> Path:
    """Write ``labels`` (``0..255``) atomically as a palette PNG (the DAVIS result format)."""
    arr = np.asarray(labels)
    if arr.ndim != 2:
        raise ValueError(f"labels must be a 2-D (H, W) array; got shape {arr.shape}")
    if arr.size and (arr.min() < 0 or arr.max() > 255):
        raise ValueError("labels must lie in 0..255 to fit a palette PNG")
    pal = np.asarray(palette, dtype=np.uint8).reshape(-1, 3)
    height, width = arr.shape
    pixels = np.ascontiguousarray(arr, dtype=np.uint8).tobytes()
    image = _pil_image().frombytes("P", (width, height), pixels)
    image.putpalette(pal.reshape(-1).tolist())
    buffer = io.BytesIO()
    image.save(buffer, format="PNG")
    path = Path(path)
    atomic_write_bytes(path, buffer.getvalue())
    return path


@dataclass(frozen=True)
class VOSSequence:
    """One DAVIS sequence (``annotation_paths`` None where the release has none, as in test-dev)."""

    name: str
    frame_paths: tuple[Path, ...]
    annotation_paths: tuple[Path | None, ...]
    image_size: tuple[int, int]
    object_ids: tuple[int, ...]

    @property
    def num_frames(self) -> int:
        """Number of frames."""
        return len(self.frame_paths)

    @property
    def frame_names(self) -> tuple[str, ...]:
        """File stems of the frames (``00000``), the names result PNGs must carry."""
        return tuple(p.stem for p in self.frame_paths)

    @property
    def has_ground_truth(self) -> bool:
        """Whether every frame has an annotation (train/val)."""
        return all(p is not None for p in self.annotation_paths)

    def read_annotation(self, index: int) -> np.ndarray:
        """Return frame ``index``'s label map ``(H, W)`` uint8 (255 = void)."""
        path = self.annotation_paths[index]
        if path is None:
            raise DataFormatError(
                self.frame_paths[index], f"frame {index} of {self.name} has no annotation"
            )
        labels = read_label_png(path)
        if labels.shape != (self.image_size[1], self.image_size[0]):
            raise DataFormatError(
                path, f"size {labels.shape[::-1]} differs from the frames' {self.image_size}"
            )
        return labels

    def read_annotations(self) -> np.ndarray:
        """Return all label maps as ``(T, H, W)`` uint8."""
        return np.stack([self.read_annotation(i) for i in range(self.num_frames)])


class DAVISDataset(SequenceDataset[VOSSequence]):
    """The sequences of one DAVIS-2017 split (None: every sequence folder)."""

    def __init__(
        self,
        root: str | Path,
        split: str | None = "val",
        resolution: str = "480p",
        year: str = "2017",
    ) -> None:
        self.root = Path(root)
        self.split = split
        self.image_dir = self.root / "JPEGImages" / resolution
        self.annotation_dir = self.root / "Annotations" / resolution
        if not self.image_dir.is_dir():
            raise DataFormatError(
                self.image_dir,
                f"frame folder missing; root= must be the DAVIS folder holding "
                f"JPEGImages/{resolution} (resolutions: {', '.join(DAVIS_RESOLUTIONS)})",
            )
        if split is None:
            names = sorted(p.name for p in self.image_dir.iterdir() if p.is_dir())
        else:
            split_file = self.root / "ImageSets" / year / f"{split}.txt"
            if not split_file.is_file():
                folder = split_file.parent
                present = sorted(p.stem for p in folder.glob("*.txt")) if folder.is_dir() else []
                raise DataFormatError(
                    split_file,
                    f"split list missing (splits found: {', '.join(present) or 'none'}; "
                    "split=None reads every sequence)",
                )
            lines = split_file.read_text().splitlines()
            # a name, not a path: each must stay inside the frame folder (and the results')
            names = [s.strip() for number, s in enumerate(lines, start=1) if s.strip()
                     and path_inside(self.image_dir, s.strip(), split_file, line=number)]
        if not names:
            raise DataFormatError(self.image_dir, "no sequences")
        self.sequence_names: list[str] = names

    def load(self, name: str) -> VOSSequence:
        """Read one sequence's file lists, size and object ids (masks load on demand)."""
        if name not in self.sequence_names:
            raise UnknownSequenceError(
                f"no DAVIS sequence '{name}' in split {self.split!r} of {self.root}; "
                f"available: {', '.join(self.sequence_names)}"
            )
        seq_dir = self.image_dir / name
        if not seq_dir.is_dir():
            raise DataFormatError(seq_dir, f"frames of sequence '{name}' missing")
        frames = tuple(sorted(p for p in seq_dir.iterdir() if p.suffix.lower() == ".jpg"))
        if not frames:
            raise DataFormatError(seq_dir, "contains no .jpg frames")
        ann_dir = self.annotation_dir / name
        pngs = {p.stem: p for p in ann_dir.glob("*.png")} if ann_dir.is_dir() else {}
        unmatched = sorted(set(pngs) - {f.stem for f in frames})
        if unmatched:
            raise DataFormatError(
                pngs[unmatched[0]], "annotation without a frame of the same name in JPEGImages"
            )
        annotations = tuple(pngs.get(f.stem) for f in frames)
        if annotations[0] is None:
            raise DataFormatError(
                ann_dir / f"{frames[0].stem}.png",
                "first-frame annotation missing; semi-supervised VOS needs it",
            )
        present = [p for p in annotations if p is not None]
        if 1 < len(present) < len(annotations):
            missing = next(i for i, p in enumerate(annotations) if p is None)
            raise DataFormatError(
                ann_dir / f"{frames[missing].stem}.png",
                f"annotation of frame {missing} missing while {len(present)} of the sequence's "
                f"{len(annotations)} frames are annotated; DAVIS annotates every frame (train, "
                "val) or only the first (test-dev), and a partly annotated sequence cannot be "
                "scored",
            )
        size = read_image_size(frames[0])
        first = read_label_png(annotations[0])
        if first.shape != (size[1], size[0]):
            raise DataFormatError(
                annotations[0], f"size {first.shape[::-1]} differs from the frames' {size}"
            )
        ids = tuple(int(v) for v in np.unique(first) if v not in (0, DAVIS_VOID_LABEL))
        if not ids:
            raise DataFormatError(
                annotations[0],
                "no object in the first annotation (labels other than 0 and 255); a DAVIS-2016 "
                "0/255 mask must be converted to labels 0/1",
            )
        if ids != tuple(range(1, ids[-1] + 1)):
            warnings.warn(
                f"{annotations[0]}: object labels {list(ids)} are not 1..{len(ids)}; the DAVIS "
                f"evaluation counts objects 1..{ids[-1]} (the absent ones as perfectly "
                "tracked), we score the labels present. Grayscale values of a converted "
                "palette image? Save the annotations as palette PNGs of labels 1..N",
                stacklevel=2)
        for path in present[1:]:
            _check_annotation(path, size)
        return VOSSequence(name, frames, annotations, size, ids)


def _check_annotation(path: Path, size: tuple[int, int]) -> None:
    """Refuse, at open, an annotation that could not be scored as the DAVIS tools score it.

    Reads the PNG header (mode and size); decodes only 8-bit grayscale files, to catch a
    DAVIS-2016 mask (0 = background, 255 = object) among DAVIS-2017 labels, where its
    object would silently become void (255) and lower J&F.
    """
    image_mod = _pil_image()
    check_image_header(path)
    try:
        with image_mod.open(path) as image:
            mode, found = image.mode, image.size
            values = np.unique(np.asarray(image)) if mode == "L" else None
    except (image_mod.DecompressionBombError, image_mod.DecompressionBombWarning) as err:
        raise DataFormatError(path, f"image too large to decode ({err})") from None
    except OSError as err:
        raise DataFormatError(path, f"missing or unreadable PNG ({err})") from err
    if mode not in ("P", "L"):
        raise DataFormatError(
            path, f"PNG mode {mode!r} is not a label map; DAVIS annotations must be palette "
                  "('P') PNGs whose indices are object ids")
    if found != tuple(size):
        raise DataFormatError(path, f"size {found} differs from the frames' {tuple(size)}")
    if values is not None and DAVIS_VOID_LABEL in values and set(values.tolist()) <= {
            0, DAVIS_VOID_LABEL}:
        raise DataFormatError(
            path, "8-bit grayscale mask with only the values 0 and 255: a DAVIS-2016 mask, whose "
                  "object (255) the DAVIS-2017 evaluation reads as void; convert it to a palette "
                  "PNG with labels 0/1 like the sequence's other annotations")


def write_davis_result(
    out_dir: str | Path, sequence: VOSSequence, index: int, labels: np.ndarray
) -> Path:
    """Write frame ``index`` of ``sequence`` as ``<out_dir>/<seq>/<frame>.png`` (DAVIS layout)."""
    expected = (sequence.image_size[1], sequence.image_size[0])
    if np.shape(labels) != expected:
        raise ValueError(f"labels have shape {np.shape(labels)}; the frame is {expected}")
    return write_label_png(
        Path(out_dir) / sequence.name / f"{sequence.frame_names[index]}.png", labels
    )
