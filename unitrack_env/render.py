"""Drawing of observations and tracks (``render_mode="rgb_array"``)."""

from __future__ import annotations

import colorsys

import cv2
import numpy as np

#: Colour of detections that are drawn underneath the tracks.
DETECTION_COLOUR = (200, 200, 200)


def id_colour(track_id: int) -> tuple[int, int, int]:
    """Return a stable, well-spread RGB colour for an id (golden-ratio hue walk)."""
    hue = (int(track_id) * 0.618033988749895) % 1.0
    r, g, b = colorsys.hsv_to_rgb(hue, 0.85, 1.0)
    return int(r * 255), int(g * 255), int(b * 255)


def draw_boxes(
    frame: np.ndarray,
    boxes: np.ndarray,
    ids: np.ndarray | None = None,
    *,
    thickness: int | None = None,
    colour: tuple[int, int, int] | None = None,
    one_based: bool = True,
) -> np.ndarray:
    """Draw ``(x, y, w, h)`` boxes on a copy of ``frame``; with ``ids``, id-coloured and labelled.

    Args:
        frame: ``uint8`` RGB image.
        boxes: ``(n, 4)`` boxes.
        ids: optional ``(n,)`` ids (colour + label).
        thickness: line width; default scales with the image size.
        colour: fixed colour when ``ids`` is None.
        one_based: boxes use MOTChallenge's 1-based pixel coordinates.
    """
    canvas = np.ascontiguousarray(frame).copy()
    if thickness is None:
        thickness = max(1, round(max(canvas.shape[:2]) / 500))
    shift = 1.0 if one_based else 0.0
    font_scale = max(0.4, max(canvas.shape[:2]) / 1600)
    for i, (x, y, w, h) in enumerate(np.asarray(boxes, dtype=np.float64).reshape(-1, 4)):
        p1 = (int(round(x - shift)), int(round(y - shift)))
        p2 = (int(round(x - shift + w)), int(round(y - shift + h)))
        c = id_colour(ids[i]) if ids is not None else (colour or DETECTION_COLOUR)
        cv2.rectangle(canvas, p1, p2, c, thickness, lineType=cv2.LINE_AA)
        if ids is not None:
            label = str(int(ids[i]))
            (tw, th), base = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, font_scale, 1)
            top = max(p1[1] - th - base - 2, 0)
            cv2.rectangle(canvas, (p1[0], top), (p1[0] + tw + 4, top + th + base + 2), c, -1)
            cv2.putText(canvas, label, (p1[0] + 2, top + th + 1), cv2.FONT_HERSHEY_SIMPLEX,
                        font_scale, (0, 0, 0), 1, cv2.LINE_AA)
    return canvas
