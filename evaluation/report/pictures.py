"""Which events of a sequence get a picture, and the picture files of each (without HTML).

The choice asks the events, not the task: ``idsw`` rows give ID-switch pictures, ``fn`` rows
bursts of misses, per-frame rows with a score below :data:`LOW` (SOT IoU, VOS J) bursts of
failures, PCK: per-frame share of points within threshold). An event's picture is its frame
with every box, joint, mask or true/predicted point pair drawn (thumbs.py), plus the frames
before and after it for the event's page. Frames are the benchmark's
``frame_array(sequence, frame)`` (by default its ``frame_image`` file, opened).
"""

from __future__ import annotations

import io
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from PIL import Image

from unitrack_env.io import atomic_write_bytes, refuse_link

from .thumbs import (
    FULL_WIDTH,
    NO_ID,
    THUMB_WIDTH,
    draw_event,
    draw_labels,
    draw_pairs,
    miss_bursts,
    overlay_masks,
    point_pairs,
    sample,
)

#: A per-frame score below this is a failure worth a picture (IoU or J; the OTB success
#: threshold most often quoted is 0.5).
LOW = 0.5
#: The quantile under which a per-frame score with no fixed bar counts as low.
WORST = 0.25
#: Per-frame scores pictured when low: ``(column, per-object column, name, bar)``; a bar of
#: None means the sequence's worst frames (:data:`WORST`). PCK (the share of points near
#: their truth) has no bar that suits every tracker and video.
PER_FRAME = (("iou", None, "IoU", LOW), ("j", "object", "J", LOW), ("pck", None, "PCK", None))
#: Width of the previous and next frames on an event's page.
NEIGHBOUR_WIDTH = 470

#: Draws a frame (1-based) for one event: the image and the crop around the event, or None.
Drawer = Callable[[int], "tuple[Image.Image, tuple] | None"]


@dataclass(frozen=True)
class Item:
    """One pictured event: what, where, and the objects it is about."""

    kind: str  # "idsw", "miss" or "low"
    frame: int
    caption: str
    gt_id: int | None = None
    track_id: int | None = None
    prev_track_id: int | None = None
    obj: int | None = None  # a VOS object (label maps are drawn)


@dataclass(frozen=True)
class Picture:
    """An event's files, relative to the report folder."""

    item: Item
    thumb: str
    full: str
    prev: str | None
    next: str | None
    page: str
    seconds: float | None = None  # the event's time in a clip of the sequence


def _int(value: Any) -> int | None:
    return None if value is None or value != value else int(value)


def _low_bursts(rows: pd.DataFrame, column: str, by: str | None,
                below: float | None) -> tuple[list[tuple[Any, int, int]], str]:
    """``(object, first frame, length)`` of each run of frames low in ``column``, and the bar.

    Low: under ``below``, or with ``below`` None the sequence's worst quarter of frames (at
    most its :data:`WORST` quantile, and under 1).
    """
    if below is None:
        cut = float(rows[column].quantile(WORST))
        low = rows[(rows[column] <= cut) & (rows[column] < 1)]
        bar = f"≤ {cut:.2f} (worst quarter of frames)"
    else:
        low, bar = rows[rows[column] < below], f"< {below}"
    ids = NO_ID if by is None else low[by].astype(int)
    return miss_bursts(pd.DataFrame({"gt_id": ids, "frame": low["frame"]})), bar


def _low_items(frames: pd.DataFrame, limit: int) -> list[Item]:
    """Bursts of frames whose per-frame score is low, at most ``limit`` of each score."""
    items = []
    for column, by, name, below in PER_FRAME:
        if column not in frames or not frames[column].notna().any():
            continue
        if by is not None and (by not in frames or not frames[by].notna().any()):
            continue
        bursts, bar = _low_bursts(frames, column, by, below)
        for ident, start, length in sample(sorted(bursts, key=lambda b: (b[1], b[0])), limit):
            value = frames.loc[frames["frame"] == start, column]
            if by is not None:
                value = frames.loc[(frames["frame"] == start) & (frames[by] == ident), column]
            what = f" object {ident}" if by is not None else ""
            items.append(Item("low", start, f"{name} {bar}{what}, frames {start}-"
                              f"{start + length - 1} ({name} {float(value.iloc[0]):.2f} at "
                              f"frame {start})", NO_ID, NO_ID, None,
                              ident if by is not None else None))
    return items


def choose(events: pd.DataFrame, limit: int) -> list[Item]:
    """At most ``limit`` events of each kind, spread evenly over the sequence."""
    items = []
    for row in sample(list(events[events["type"] == "idsw"].itertuples()), limit):
        track, prev = _int(row.track_id), _int(row.prev_track_id)
        items.append(Item("idsw", int(row.frame), f"switch, frame {int(row.frame)}: gt "
                          f"{int(row.gt_id)} track {prev} → {track}", int(row.gt_id), track,
                          prev))
    fn = events[(events["type"] == "fn") & events["gt_id"].notna()]
    for gt_id, start, length in sample(sorted(miss_bursts(fn), key=lambda b: (b[1], b[0])),
                                       limit):
        items.append(Item("miss", start, f"miss, frames {start}-{start + length - 1}: gt "
                          f"{gt_id}", gt_id))
    return items + _low_items(events[events["type"] == "frame"], limit)


#: Per frame (1-based): the ground-truth and result masks, ``{id: (H, W) bool}`` each.
Masks = Callable[[int], "tuple[dict[int, np.ndarray], dict[int, np.ndarray]]"]


def mask_tables(bench: Any, run: Path, sequence: str, info: Any) -> Masks | None:
    """The masks of each frame when the run's results are mask tables (MOTS), else None."""
    ground_truth = getattr(bench.dataset, "ground_truth", None)
    if not callable(ground_truth) or not hasattr(info, "height"):
        return None
    try:
        results = bench.read(run / "data", sequence)
        gt = ground_truth(sequence)
    except (OSError, ValueError):
        return None
    if gt is None or not all(hasattr(t, "decode") and hasattr(t, "rows") for t in (gt, results)):
        return None
    first = int(getattr(info, "first_frame", 1))

    def at(frame: int) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
        out = []
        for table in (gt, results):
            idx = table.rows(first + frame - 1)
            masks = table.decode(idx, info.height, info.width) if len(idx) else []
            out.append({int(table.ids[i]): m for i, m in zip(idx, masks, strict=True)})
        return out[0], out[1]
    return at


def drawer(bench: Any, run: Path, sequence: str, events: pd.DataFrame, item: Item,
           frames: Callable[[int], Image.Image | None], loaded: Any,
           masks: Masks | None = None) -> Drawer:
    """How to draw ``item``'s frames.

    Label maps for an object (VOS), else true/predicted point pairs where the frame's rows
    pair positions, else the events' boxes, over the masks of mask tables.
    """
    by_frame = {int(f): g for f, g in events.groupby("frame")}
    read_result = getattr(bench, "read_frame", None)
    if item.obj is not None and callable(read_result) and hasattr(loaded, "read_annotation"):
        def labels(frame: int) -> tuple[Image.Image, tuple] | None:
            image = frames(frame)
            if image is None:
                return None
            result = read_result(run / "data", loaded, frame - 1)
            return draw_labels(image, loaded.read_annotation(frame - 1), result, item.obj)
        return labels

    def boxes(frame: int) -> tuple[Image.Image, tuple] | None:
        picture = frames(frame)
        if picture is None:
            return None
        rows = by_frame.get(frame, events.iloc[:0])
        pairs = point_pairs(rows)
        if len(pairs):
            return draw_pairs(picture, pairs)
        if masks is not None:
            picture = overlay_masks(picture, *masks(frame), item.gt_id, item.track_id,
                                    item.prev_track_id)
        return draw_event(picture, rows, item.gt_id,
                          item.track_id, item.prev_track_id)
    return boxes


def _scaled(img: Image.Image, width: int) -> Image.Image:
    if img.width <= width:
        return img
    return img.resize((width, max(1, round(img.height * width / img.width))))


def _save_jpeg(img: Image.Image, path: Path, quality: int) -> None:
    """Write ``img`` as a new file renamed in place (never through a link at ``path``)."""
    data = io.BytesIO()
    img.save(data, format="JPEG", quality=quality)
    atomic_write_bytes(path, data.getvalue())


def write_files(draw: Drawer, item: Item, folder: Path, name: str) -> Picture | None:
    """Write the thumbnail, the full frame and its neighbours of ``item`` (kept if present)."""
    rel = folder.name
    names = {k: f"{name}{suffix}.jpg" for k, suffix in
             (("thumb", ""), ("full", "-full"), ("prev", "-prev"), ("next", "-next"))}
    if not all((folder / names[k]).is_file() for k in ("thumb", "full")):
        drawn = draw(item.frame)
        if drawn is None:
            return None
        img, crop = drawn
        small = img.crop(crop)
        small = small.resize((THUMB_WIDTH, max(1, round(small.height * THUMB_WIDTH
                                                         / small.width))))
        refuse_link(folder)  # pictures go in a folder of the report's, never via a link
        folder.mkdir(parents=True, exist_ok=True)
        _save_jpeg(small, folder / names["thumb"], 90)
        _save_jpeg(_scaled(img, FULL_WIDTH), folder / names["full"], 80)
        for key, frame in (("prev", item.frame - 1), ("next", item.frame + 1)):
            near = draw(frame) if frame >= 1 else None
            if near is not None:
                _save_jpeg(_scaled(near[0], NEIGHBOUR_WIDTH), folder / names[key], 80)
    near = {k: f"{rel}/{names[k]}" if (folder / names[k]).is_file() else None
            for k in ("prev", "next")}
    return Picture(item, f"{rel}/{names['thumb']}", f"{rel}/{names['full']}", near["prev"],
                   near["next"], f"{rel}/{name}.html")


def event_pictures(bench: Any, run: Path, sequence: str, events: pd.DataFrame, folder: Path,
                   limit: int) -> list[Picture]:
    """The pictures of a sequence's chosen events (none when its frames are not here)."""
    items = choose(events, limit)
    if not items:
        return []
    try:
        loaded = bench.sequence_info(sequence)
        bench.frame_image(sequence, 1)
        rate = bench.frame_rate(sequence)
    except (OSError, ValueError, KeyError, AttributeError):  # data moved or not ours to read
        return []

    def frames(frame: int) -> Image.Image | None:
        array = bench.frame_array(sequence, frame) if frame >= 1 else None
        return None if array is None else Image.fromarray(array)
    masks = mask_tables(bench, run, sequence, loaded)
    pictures = []
    for item in items:
        name = f"{item.kind}-f{item.frame:06d}-" + (
            f"o{item.obj}" if item.obj is not None else f"g{item.gt_id}")
        picture = write_files(drawer(bench, run, sequence, events, item, frames, loaded,
                                     masks), item, folder, name)
        if picture is not None:
            seconds = (item.frame - 1) / float(rate) if rate else None
            pictures.append(replace(picture, seconds=seconds))
    return pictures

