"""Need for Speed (NfS) reader (``<seq>/<fps>/<seq>/%05d.jpg``, ``<seq>/<fps>/<seq>.txt``).

The annotation files are VATIC text exports (the tool NfS was labelled with,
github.com/cvondrick/vatic): one row per 240 fps frame, space-separated,
``track_id xmin ymin xmax ymax frame lost occluded generated "label"``. The frame column
starts at 0 in some files and at 1 in others, so rows are taken in order, as the ``got10k``
package's ``NfS`` reader does. A ``30/<seq>.txt`` that holds the 240 fps rows (about 8 per
30 fps image) is cut to every eighth row from the first (240 fps frames 1, 9, 17, ...: the
30 fps video's frames), and a row or an image left over at the end (the two videos differ
by one frame in places) is dropped, as the got10k and trackit NfS readers do.
"""

from __future__ import annotations

import shlex
from pathlib import Path

import numpy as np

from unitrack_env.datasets.base import SequenceDataset
from unitrack_env.datasets.limits import MAX_TEXT_BYTES, read_limited
from unitrack_env.datasets.otb import _check_boxes
from unitrack_env.datasets.sot import SOTSequence, numbered_images, read_image_size
from unitrack_env.datasets.synthetic.cache import SyntheticKind
from unitrack_env.datasets.synthetic.otb import render_target, write_images
from unitrack_env.datasets.synthetic.scene_model import SceneConfig
from unitrack_env.errors import DataFormatError, UnknownSequenceError

#: ``variant=`` values: the frame rate folder read (``"30"``, the one papers report, default).
NFS_VARIANTS = ("30", "240")
#: 240 fps frames per 30 fps frame.
NFS_STEP = 8
#: The numeric columns of a VATIC row, as errors name them.
VATIC_FIELDS = ("track_id", "xmin", "ymin", "xmax", "ymax", "frame", "lost", "occluded",
                "generated")


def read_vatic(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Read an NfS annotation: ``(rows, 4)`` boxes ``x, y, w, h`` and the ``lost`` flags.

    ``w = xmax - xmin`` and ``h = ymax - ymin`` (the got10k package's conversion). A row
    without the nine numbers and a quoted label raises DataFormatError naming its line.
    """
    try:
        text = read_limited(path, MAX_TEXT_BYTES, "annotation").decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise DataFormatError(path, f"cannot read annotation ({err})") from err
    rows: list[list[float]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            parts = shlex.split(line)
        except ValueError:
            raise DataFormatError(path, "unbalanced quotes around the label", line=number) from None
        if len(parts) < len(VATIC_FIELDS) + 1:
            raise DataFormatError(path, f"expected {' '.join(VATIC_FIELDS)} \"label\", found "
                                        f"{len(parts)} values: {line.strip()!r}", line=number)
        values = []
        for field, part in zip(VATIC_FIELDS, parts, strict=False):
            try:
                values.append(float(part))
            except ValueError:
                raise DataFormatError(path, f"not a number: {part!r}", line=number,
                                      field=field) from None
        rows.append(values)
    if not rows:
        raise DataFormatError(path, "contains no annotation rows")
    table = np.asarray(rows)
    boxes = np.column_stack([table[:, 1:3], table[:, 3:5] - table[:, 1:3]])
    return boxes, table[:, 6] != 0


class NfSDataset(SequenceDataset[SOTSequence]):
    """NfS: ``<root>/<seq>/<V>/<seq>/%05d.jpg`` and ``<root>/<seq>/<V>/<seq>.txt``.

    ``<V>`` is ``30`` (``variant="30"``, default) or ``240``. ``absent`` holds the
    annotation's ``lost`` flags (the target outside the view; the OTB rules NfS is scored by
    do not use them). A sequence folder without the variant's annotation is not listed.
    """

    def __init__(self, root: str | Path, variant: str | None = None) -> None:
        self.root = Path(root)
        self.variant = "30" if variant is None else str(variant)
        if self.variant not in NFS_VARIANTS:
            raise ValueError(f"NfS variant {variant!r}; valid: {', '.join(NFS_VARIANTS)}")
        if not self.root.is_dir():
            raise DataFormatError(self.root, "NfS root folder missing")
        self._anno = {p.name: p / self.variant / f"{p.name}.txt"
                      for p in sorted(self.root.iterdir())
                      if (p / self.variant / f"{p.name}.txt").is_file()}
        if not self._anno:
            raise DataFormatError(self.root, f"no <seq>/{self.variant}/<seq>.txt annotation found")
        self.sequence_names: list[str] = list(self._anno)

    def load(self, name: str) -> SOTSequence:
        """Read one sequence; DataFormatError naming the file when it cannot be played."""
        if name not in self._anno:
            raise UnknownSequenceError(f"no NfS sequence '{name}' in {self.root}")
        anno = self._anno[name]
        boxes, lost = read_vatic(anno)
        images = numbered_images(anno.parent / name)
        numbers = sorted(images)
        if len(boxes) != len(numbers) and abs(len(boxes) / len(numbers) - NFS_STEP) < 1:
            boxes, lost = boxes[::NFS_STEP], lost[::NFS_STEP]  # 240 fps rows for 30 fps frames
        if abs(len(boxes) - len(numbers)) == 1:
            kept = min(len(boxes), len(numbers))
            boxes, lost, numbers = boxes[:kept], lost[:kept], numbers[:kept]
        if len(boxes) != len(numbers):
            raise DataFormatError(anno, f"has {len(boxes)} rows but the frame folder holds "
                                        f"{len(numbers)} frames")
        _check_boxes(anno, boxes, 0)
        frames = tuple(images[n] for n in numbers)
        return SOTSequence(name, frames, tuple(numbers), boxes, read_image_size(frames[0]),
                           lost, f"NfS-{self.variant}")


_SCENE = {"num_objects": 3, "num_crossings": 1, "num_static_persons": 0, "num_occluders": 1,
          "object_height_range": (60.0, 100.0), "speed_range": (0.4, 0.8),
          "max_vertical_speed": 0.1}
#: The synthetic default: name, scene at 240 fps (the 30 fps video keeps every eighth frame),
#: 240 fps frames written. ``synball_2`` ends one 30 fps image after its last annotated
#: frame (the leftover-image case of the release the reader drops).
SYNTHETIC_NFS = (
    ("synwalk_1", SceneConfig(width=320, height=240, num_frames=81, seed=0, **_SCENE), 81),
    ("synball_2", SceneConfig(width=360, height=240, num_frames=73, seed=4, **_SCENE), 72),
)


def _vatic_rows(boxes: np.ndarray, lost: np.ndarray) -> list[str]:
    return [f"1 {x:.0f} {y:.0f} {x + w:.0f} {y + h:.0f} {i + 1} {int(gone)} 0 0 \"person\"\n"
            for i, ((x, y, w, h), gone) in enumerate(zip(boxes, lost, strict=True))]


def write_synthetic_nfs(root: Path, benchmark: str = "NfS") -> None:
    """Write :data:`SYNTHETIC_NFS` in NfS's layout; ``30/<seq>.txt`` holds the 240 fps rows."""
    for name, scene, annotated in SYNTHETIC_NFS:
        images, boxes, visibility = render_target(scene)
        rows = _vatic_rows(boxes[:annotated], visibility[:annotated] == 0)
        for fps, step in (("240", 1), ("30", NFS_STEP)):
            kept = range(0, annotated if fps == "240" else len(images), step)
            folder = Path(root) / name / fps
            write_images(folder / name, [images[i] for i in kept],
                         [f"{k + 1:05d}.jpg" for k in range(len(kept))])
            (folder / f"{name}.txt").write_text("".join(rows))


def synthetic_nfs_frames(benchmark: str = "NfS", split: str | None = None) -> dict[str, int]:
    """Frames of each synthetic 30 fps sequence (as read), known before writing."""
    return {name: (annotated - 1) // NFS_STEP + 1 for name, _, annotated in SYNTHETIC_NFS}


#: NfS's embedded synthetic default.
NFS_SYNTHETIC = SyntheticKind("nfs", write_synthetic_nfs, ("NfS",), synthetic_nfs_frames)
