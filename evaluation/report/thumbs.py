"""Pictures of error events: a thumbnail around the event and the full frame, boxes drawn.

Colours (also the legend of the report): ground truth green, the track matched at the event
red, the track the ground truth was matched to before a switch blue, other tracks grey. The
event's objects are thick and labelled ("gt 9", "track 4"); every other object is thin and
faded, with its id.
Which events get pictures, and their files: pictures.py.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from PIL import Image, ImageDraw, ImageFilter, ImageFont

GT_COLOUR = (0, 220, 0)
TRACK_COLOUR = (255, 0, 0)
PREVIOUS_COLOUR = (0, 90, 255)
OTHER_COLOUR = (200, 200, 200)

#: Thumbnail width in pixels; full frames are scaled to at most FULL_WIDTH.
THUMB_WIDTH = 220
FULL_WIDTH = 960


#: Opacity of the objects that are not the event's (thin and faded, drawn first).
CONTEXT_ALPHA = 130
#: Id of an object whose rows carry none (SOT's target and prediction).
NO_ID = -1


@dataclass(frozen=True)
class Shape:
    """One drawn object: a box ``(x, y, w, h)`` or joints ``(k, 2)``, its side and id."""

    side: str  # "gt" or "track"
    ident: int
    box: tuple[float, float, float, float] | None
    points: tuple[tuple[float, float], ...] = ()

    def extent(self) -> tuple[float, float, float, float]:
        """``(x, y, w, h)`` around the shape."""
        if self.box is not None:
            return self.box
        xs, ys = [p[0] for p in self.points], [p[1] for p in self.points]
        return (min(xs), min(ys), max(xs) - min(xs), max(ys) - min(ys))


def frame_shapes(frame_events: pd.DataFrame) -> list[Shape]:
    """The ground truth and tracks of one frame's events, one shape per side and id.

    Boxes where the rows have a size, joints where they have positions only (PoseTrack).
    """
    shapes = []
    for side, cols, id_col in (("gt", ("x", "y", "w", "h"), "gt_id"),
                               ("track", ("tx", "ty", "tw", "th"), "track_id")):
        if cols[0] not in frame_events or id_col not in frame_events:
            continue
        rows = frame_events.dropna(subset=[cols[0], cols[1]])
        ids = pd.to_numeric(rows[id_col], errors="coerce").fillna(NO_ID).astype(int)
        for ident, group in rows.groupby(ids.to_numpy(), sort=True):
            sized = group.dropna(subset=[cols[2], cols[3]])
            if len(sized):
                first = sized.iloc[0]
                shapes.append(Shape(side, int(ident), tuple(float(first[c]) for c in cols)))
            else:
                points = group[[cols[0], cols[1]]].drop_duplicates().to_numpy(float)
                shapes.append(Shape(side, int(ident), None, tuple(map(tuple, points))))
    return shapes


def _style(shape: Shape, gt_id: int | None, track_id: int | None,
           prev_track_id: int | None) -> tuple[tuple[int, int, int], str | None]:
    """(colour, label of an event object or None for context)."""
    if shape.side == "gt":
        name = "gt" if shape.ident == NO_ID else f"gt {shape.ident}"
        return GT_COLOUR, name if gt_id is not None and shape.ident == gt_id else None
    name = "track" if shape.ident == NO_ID else f"track {shape.ident}"
    if track_id is not None and shape.ident == track_id:
        return TRACK_COLOUR, name
    if prev_track_id is not None and shape.ident == prev_track_id:
        return PREVIOUS_COLOUR, name
    return OTHER_COLOUR, None


def _font(size: int) -> ImageFont.ImageFont | ImageFont.FreeTypeFont:
    try:
        return ImageFont.load_default(size=size)
    except (TypeError, OSError):  # Pillow without FreeType: the fixed bitmap font
        return ImageFont.load_default()


def _label(draw: ImageDraw.ImageDraw, xy: tuple[float, float], text: str,
           colour: tuple[int, ...], font: ImageFont.ImageFont | ImageFont.FreeTypeFont,
           below: bool = False) -> None:
    """``text`` on a patch of ``colour`` above ``xy`` (below it with ``below``), in the frame."""
    if not text:
        return
    left, top, right, bottom = draw.textbbox((0, 0), text, font=font)
    w, h = right - left + 4, bottom - top + 4
    size = draw.im.size
    x = min(max(0.0, xy[0]), size[0] - w)
    y = xy[1] if below else xy[1] - h
    y = min(max(0.0, y), size[1] - h)
    draw.rectangle([x, y, x + w, y + h], fill=colour)
    ink = (0, 0, 0, colour[3] if len(colour) > 3 else 255)
    draw.text((x + 2 - left, y + 2 - top), text, fill=ink, font=font)


def _draw_shape(draw: ImageDraw.ImageDraw, shape: Shape, colour: tuple[int, ...], width: int,
                text: str, font: ImageFont.ImageFont | ImageFont.FreeTypeFont) -> None:
    """A box or joints; the ground truth's label below it, a track's above."""
    below = shape.side == "gt"
    if shape.box is not None:
        x, y, w, h = shape.box
        draw.rectangle([x, y, x + w, y + h], outline=colour, width=width)
        anchor = (x, y + h + width) if below else (x, y - width)
    else:
        r = width + 1
        for px, py in shape.points:
            draw.ellipse([px - r, py - r, px + r, py + r], outline=colour, width=max(1, width // 2))
        x, y, w, h = shape.extent()
        anchor = (x, y + h + r) if below else (x, y - r)
    _label(draw, anchor, text, colour, font, below)


def draw_event(image: Image.Image, frame_events: pd.DataFrame, gt_id: int | None,
               track_id: int | None, prev_track_id: int | None) -> tuple[Image.Image, tuple]:
    """The frame with every object drawn and labelled with its id; also the crop around the event.

    The event's ground truth and tracks are thick and in colour, the others thin and faded.
    """
    img = image.convert("RGBA")
    context = Image.new("RGBA", img.size, (0, 0, 0, 0))
    faded = ImageDraw.Draw(context)
    thin, thick = max(1, round(img.width / 700)), max(3, round(img.width / 220))
    small, big = _font(max(10, round(img.width / 90))), _font(max(12, round(img.width / 55)))
    focus, events = [], []
    for shape in frame_shapes(frame_events):
        colour, name = _style(shape, gt_id, track_id, prev_track_id)
        if name is None:
            _draw_shape(faded, shape, (*colour, CONTEXT_ALPHA), thin,
                        "" if shape.ident == NO_ID else str(shape.ident), small)
        else:
            events.append((shape, colour, name))
            focus.append(shape.extent())
    img = Image.alpha_composite(img, context)
    draw = ImageDraw.Draw(img)
    for shape, colour, name in events:
        _draw_shape(draw, shape, (*colour, 255), thick, name, big)
    return img.convert("RGB"), _crop(focus, img.size)


#: Frames narrower than this are enlarged (by a whole factor) before points are drawn.
POINTS_WIDTH = 512
#: Event type of a pair whose predicted occlusion flag is wrong.
FLAG_ERROR = "occlusion_error"


def point_pairs(frame_events: pd.DataFrame) -> pd.DataFrame:
    """The rows of one frame that pair a true and a predicted position of an object, no size."""
    cols = ("object", "x", "y", "tx", "ty")
    if not all(c in frame_events for c in cols):
        return frame_events.iloc[:0]
    rows = frame_events.dropna(subset=list(cols))
    if "w" in rows:
        rows = rows[rows["w"].isna()]
    return rows


def draw_pairs(image: Image.Image, pairs: pd.DataFrame) -> tuple[Image.Image, tuple]:
    """Each true point green and its prediction red, joined by a line and labelled with its id.

    A point occluded in the ground truth (no ``distance``) is a hollow green ring; a prediction
    that says occluded (its flag the truth's, or the other one in a ``FLAG_ERROR`` row) is a
    hollow red ring. A small frame is enlarged first (to at least :data:`POINTS_WIDTH`), so
    that the marks and ids stay legible. Also the crop around all the points.
    """
    scale = max(1, POINTS_WIDTH // max(1, image.width))
    img = image.convert("RGB").resize((image.width * scale, image.height * scale))
    draw = ImageDraw.Draw(img)
    r, width = max(3, round(img.width / 90)), max(1, round(img.width / 200))
    font = _font(max(10, round(img.width / 30)))
    focus = []
    for row in pairs.itertuples():  # the lines first, under every dot
        draw.line([(row.x * scale, row.y * scale), (row.tx * scale, row.ty * scale)],
                  fill=OTHER_COLOUR, width=width)
    for row in pairs.itertuples():
        truth, guess = (row.x * scale, row.y * scale), (row.tx * scale, row.ty * scale)
        hidden = "distance" in pairs and row.distance != row.distance
        said_hidden = hidden != (row.type == FLAG_ERROR)
        for (px, py), colour, hollow, size in ((truth, GT_COLOUR, hidden, r + 2),
                                               (guess, TRACK_COLOUR, said_hidden, r)):
            box = [px - size, py - size, px + size, py + size]  # a hit: red inside green
            if hollow:
                draw.ellipse(box, outline=colour, width=width)
            else:
                draw.ellipse(box, fill=colour, outline=(0, 0, 0))
        _label(draw, (truth[0] + r, truth[1] - r), str(int(row.object)), GT_COLOUR, font)
        focus.append((min(truth[0], guess[0]), min(truth[1], guess[1]),
                      abs(truth[0] - guess[0]), abs(truth[1] - guess[1])))
    return img, _crop(focus, img.size)


def _outline(mask: np.ndarray, width: int) -> np.ndarray:
    """The pixels of ``mask`` within ``width`` of its border."""
    inner = Image.fromarray(mask.astype(np.uint8) * 255).filter(
        ImageFilter.MinFilter(2 * width + 1))
    return mask & (np.asarray(inner) == 0)


def _mask_box(mask: np.ndarray) -> tuple[float, float, float, float] | None:
    ys, xs = np.nonzero(mask)
    if not len(xs):
        return None
    return (float(xs.min()), float(ys.min()), float(xs.max() - xs.min() + 1),
            float(ys.max() - ys.min() + 1))


def overlay_masks(image: Image.Image, gt: dict[int, np.ndarray], tracks: dict[int, np.ndarray],
                  gt_id: int | None, track_id: int | None,
                  prev_track_id: int | None) -> Image.Image:
    """Masks under the boxes (MOTS).

    The event's tracks are filled in their colour and its ground truth outlined green; the
    other masks are faded.
    """
    canvas = np.asarray(image.convert("RGB"), dtype=np.float32).copy()
    thin, thick = max(1, round(image.width / 700)), max(2, round(image.width / 250))
    for ident, mask in tracks.items():
        colour = {track_id: TRACK_COLOUR, prev_track_id: PREVIOUS_COLOUR}.get(ident)
        alpha = 0.2 if colour is None else 0.45
        if mask.shape == canvas.shape[:2]:
            canvas[mask] = (1 - alpha) * canvas[mask] + alpha * np.asarray(
                colour or OTHER_COLOUR, np.float32)
    for ident, mask in gt.items():
        if mask.shape == canvas.shape[:2]:
            edge = _outline(mask, thick if ident == gt_id else thin)
            canvas[edge] = (GT_COLOUR if ident == gt_id
                            else 0.5 * canvas[edge] + 0.5 * np.asarray(GT_COLOUR))
    return Image.fromarray(canvas.clip(0, 255).astype(np.uint8))


def draw_labels(image: Image.Image, gt: np.ndarray, result: np.ndarray,
                obj: int) -> tuple[Image.Image, tuple]:
    """A frame with label maps (VOS); also the crop around object ``obj``.

    The result of ``obj`` is filled red and its ground truth outlined green, thick and
    labelled; the other objects are faded.
    """
    img = image.convert("RGB")
    if img.size != gt.shape[::-1]:
        img = img.resize(gt.shape[::-1])
    canvas = np.asarray(img, dtype=np.float32).copy()
    thin, thick = max(1, round(img.width / 500)), max(2, round(img.width / 200))
    objects = sorted((set(np.unique(gt)) | set(np.unique(result))) - {0, 255})
    shapes = []
    for label in objects:
        focus = int(label) == obj
        fill, alpha = (TRACK_COLOUR, 0.45) if focus else (OTHER_COLOUR, 0.25)
        mine = result == label
        canvas[mine] = (1 - alpha) * canvas[mine] + alpha * np.asarray(fill, np.float32)
        edge = _outline(gt == label, thick if focus else thin)
        canvas[edge] = GT_COLOUR if focus else 0.5 * canvas[edge] + 0.5 * np.asarray(GT_COLOUR)
        for side, mask in (("gt", gt == label), ("track", mine)):
            box = _mask_box(mask)
            if box is not None:
                shapes.append(Shape(side, int(label), box))
    drawn = Image.fromarray(canvas.clip(0, 255).astype(np.uint8))
    draw = ImageDraw.Draw(drawn)
    font = _font(max(12, round(img.width / 55)))
    focus = [s.extent() for s in shapes if s.ident == obj]
    for shape in shapes:
        if shape.ident == obj:
            colour = GT_COLOUR if shape.side == "gt" else TRACK_COLOUR
            text = f"gt object {obj}" if shape.side == "gt" else f"object {obj}"
            x, y, _, h = shape.box
            _label(draw, (x, y if shape.side == "gt" else y + h + 16), text, colour, font)
        elif shape.side == "gt":
            _label(draw, shape.box[:2], str(shape.ident), (*OTHER_COLOUR,), _font(11))
    return drawn, _crop(focus, drawn.size)


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


def miss_bursts(fn: pd.DataFrame) -> list[tuple[int, int, int]]:
    """``(gt_id, first frame, length)`` of each run of consecutive missed frames of a gt id."""
    out = []
    for gt_id, frames in fn.groupby("gt_id")["frame"]:
        values = sorted({int(f) for f in frames})  # PoseTrack: a row per joint
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
