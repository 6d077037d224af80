"""Pictures of error events: a thumbnail around the event and the full frame, boxes drawn.

Colours (also the legend of the report): ground truth green, the track matched at the event
red, the track the ground truth was matched to before a switch blue, other tracks grey.
Thumbnails are JPEG files beside the report, named after the event; an event's picture is
drawn once and reused when the report is rebuilt.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import pandas as pd
from PIL import Image, ImageDraw

from unitrack_env.io import atomic_write_bytes, refuse_link

GT_COLOUR = (0, 220, 0)
TRACK_COLOUR = (255, 0, 0)
PREVIOUS_COLOUR = (0, 90, 255)
OTHER_COLOUR = (200, 200, 200)

#: Thumbnail width in pixels; full frames are scaled to at most FULL_WIDTH.
THUMB_WIDTH = 220
FULL_WIDTH = 960


@dataclass(frozen=True)
class Picture:
    """One event picture: what it shows and where its files are (relative to the report)."""

    sequence: str
    frame: int
    kind: str  # "idsw" or "miss"
    caption: str
    thumb: str
    full: str


def _boxes(frame_events: pd.DataFrame, kinds: tuple[str, ...], prefix: str) -> pd.DataFrame:
    cols = ["x", "y", "w", "h"] if prefix == "" else ["tx", "ty", "tw", "th"]
    rows = frame_events[frame_events["type"].isin(kinds)]
    rows = rows.dropna(subset=cols[:1])
    return rows.assign(bx=rows[cols[0]], by=rows[cols[1]], bw=rows[cols[2]], bh=rows[cols[3]])


def _rect(draw: ImageDraw.ImageDraw, box: tuple[float, ...], colour: tuple[int, int, int],
          width: int) -> None:
    x, y, w, h = box
    draw.rectangle([x, y, x + w, y + h], outline=colour, width=width)


def draw_event(image: Image.Image, frame_events: pd.DataFrame, gt_id: int,
               track_id: int | None, prev_track_id: int | None) -> tuple[Image.Image, tuple]:
    """The frame with every box drawn; returns it and the crop box around the event."""
    img = image.convert("RGB")
    draw = ImageDraw.Draw(img)
    line = max(2, round(img.width / 300))
    tracks = _boxes(frame_events, ("tp", "fp"), "t").drop_duplicates("track_id")
    gts = _boxes(frame_events, ("tp", "fn"), "").drop_duplicates("gt_id")
    focus = []
    for row in tracks.itertuples():
        box = (row.bx, row.by, row.bw, row.bh)
        if track_id is not None and row.track_id == track_id:
            colour = TRACK_COLOUR
        elif prev_track_id is not None and row.track_id == prev_track_id:
            colour = PREVIOUS_COLOUR
        else:
            colour = OTHER_COLOUR
        if colour != OTHER_COLOUR:
            focus.append(box)
        _rect(draw, box, colour, line)
    for row in gts.itertuples():
        box = (row.bx, row.by, row.bw, row.bh)
        _rect(draw, box, GT_COLOUR, line)
        if row.gt_id == gt_id:
            focus.append(box)
    return img, _crop(focus, img.size)


def _crop(boxes: list[tuple], size: tuple[int, int]) -> tuple[int, int, int, int]:
    """A region around ``boxes`` with margin, at least a quarter of the frame wide."""
    if not boxes:
        return (0, 0, size[0], size[1])
    x0 = min(b[0] for b in boxes)
    y0 = min(b[1] for b in boxes)
    x1 = max(b[0] + b[2] for b in boxes)
    y1 = max(b[1] + b[3] for b in boxes)
    side = max(x1 - x0, y1 - y0, size[0] / 4) * 1.4
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    left = int(max(0, min(size[0] - side, cx - side / 2)))
    top = int(max(0, min(size[1] - side, cy - side / 2)))
    return (left, top, int(min(size[0], left + side)), int(min(size[1], top + side)))


def render_picture(frame_path: Path, frame_events: pd.DataFrame, out: Path, name: str, *,
                   gt_id: int, track_id: int | None = None,
                   prev_track_id: int | None = None) -> tuple[str, str]:
    """Write ``<name>.jpg`` (thumbnail) and ``<name>-full.jpg`` under ``out``; relative paths."""
    thumb, full = out / f"{name}.jpg", out / f"{name}-full.jpg"
    if not (thumb.is_file() and full.is_file()):
        with Image.open(frame_path) as image:
            img, crop = draw_event(image, frame_events, gt_id, track_id, prev_track_id)
        small = img.crop(crop)
        small = small.resize((THUMB_WIDTH, max(1, round(small.height * THUMB_WIDTH
                                                         / small.width))))
        refuse_link(out)  # pictures go in a folder of the report's, never via a link
        if img.width > FULL_WIDTH:
            img = img.resize((FULL_WIDTH, round(img.height * FULL_WIDTH / img.width)))
        for picture, path, quality in ((small, thumb, 90), (img, full, 80)):
            data = io.BytesIO()
            picture.save(data, format="JPEG", quality=quality)
            atomic_write_bytes(path, data.getvalue())
    return f"{out.name}/{thumb.name}", f"{out.name}/{full.name}"


def miss_bursts(fn: pd.DataFrame) -> list[tuple[int, int, int]]:
    """``(gt_id, first frame, length)`` of each run of consecutive missed frames of a gt id."""
    out = []
    for gt_id, frames in fn.groupby("gt_id")["frame"]:
        values = sorted(int(f) for f in frames)
        start = prev = values[0]
        for f in values[1:] + [None]:
            if f is not None and f == prev + 1:
                prev = f
                continue
            out.append((int(gt_id), start, prev - start + 1))
            if f is not None:
                start = prev = f
    return out


def sample(items: list, limit: int) -> list:
    """At most ``limit`` items spread evenly over the list (its order kept)."""
    if len(items) <= limit:
        return list(items)
    step = len(items) / limit
    return [items[int(i * step)] for i in range(limit)]
