"""Drawing of observations and tracks (``render_mode="rgb_array"``).

Every environment draws with these functions: id-coloured boxes (MOT, SOT), masks (MOTS,
VIS), label maps (VOS) and skeletons (pose tasks).
"""

from __future__ import annotations

import colorsys

import cv2
import numpy as np

from unitrack_env.spaces.masks import mask_boxes

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

    ``thickness`` defaults to a size-scaled width; ``one_based`` reads MOTChallenge's 1-based
    pixel coordinates.
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


#: Opacity of the mask overlay of :func:`draw_masks`.
MASK_ALPHA = 0.55
#: Opacity of the label overlay of :func:`overlay_labels`.
OVERLAY_ALPHA = 0.5
#: The label of void pixels in label maps (DAVIS's), never drawn.
VOID_LABEL = 255


def draw_masks(frame: np.ndarray, masks: np.ndarray, ids: np.ndarray | None = None
               ) -> np.ndarray:
    """Overlay ``(n, H, W)`` masks on a copy of ``frame``.

    With ``ids`` the masks are id-coloured and get labelled boxes, else they are grey. A frame
    of another size (``decode_frames=False``) is replaced by a black canvas of the masks' size.
    """
    canvas = np.ascontiguousarray(frame).copy()
    if len(masks) and canvas.shape[:2] != masks.shape[1:]:
        canvas = np.zeros((*masks.shape[1:], 3), dtype=np.uint8)
    for i, mask in enumerate(masks):
        colour = np.asarray(id_colour(ids[i]) if ids is not None else DETECTION_COLOUR, float)
        canvas[mask] = (canvas[mask] * (1 - MASK_ALPHA) + colour * MASK_ALPHA).astype(np.uint8)
    if ids is not None and len(masks):
        canvas = draw_boxes(canvas, mask_boxes(masks), ids, one_based=False)
    return canvas


def overlay_labels(frame: np.ndarray, labels: np.ndarray, alpha: float = OVERLAY_ALPHA
                   ) -> np.ndarray:
    """Draw every object of ``labels`` on ``frame``: a translucent fill and an outline.

    Object ``k`` gets :func:`id_colour` ``(k)``; void pixels are skipped; a frame of another
    size (``decode_frames=False``) is replaced by a black canvas.
    """
    if frame.shape[:2] != labels.shape:
        frame = np.zeros((*labels.shape, 3), dtype=np.uint8)
    canvas = frame.astype(np.float32)
    thickness = max(1, round(max(labels.shape) / 400))
    outlines = []
    for label in np.unique(labels):
        if label in (0, VOID_LABEL):
            continue
        mask = labels == label
        colour = np.asarray(id_colour(int(label)), dtype=np.float32)
        canvas[mask] = (1.0 - alpha) * canvas[mask] + alpha * colour
        contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL,
                                       cv2.CHAIN_APPROX_SIMPLE)
        outlines.append((contours, id_colour(int(label))))
    out = np.clip(np.round(canvas), 0, 255).astype(np.uint8)
    for contours, colour in outlines:
        cv2.drawContours(out, contours, -1, colour, thickness, lineType=cv2.LINE_AA)
    return out


def joint_colours(count: int) -> list[tuple[int, int, int]]:
    """Return ``count`` well-spread RGB colours (one per joint)."""
    return [tuple(int(255 * c) for c in colorsys.hsv_to_rgb(i / max(count, 1), 0.9, 1.0))
            for i in range(count)]  # type: ignore[misc]


def draw_skeleton(
    canvas: np.ndarray,
    points: np.ndarray,
    limbs: tuple[tuple[int, int], ...],
    *,
    present: np.ndarray | None = None,
    colour: tuple[int, int, int] | None = None,
    joint_colours_: list[tuple[int, int, int]] | None = None,
) -> None:
    """Draw one skeleton in place: limbs (0-based joint pairs) and the ``present`` joints' dots.

    ``colour`` colours the whole skeleton, else ``joint_colours_`` each joint.
    """
    pts = np.asarray(points, dtype=np.float64)
    ok = np.all(np.isfinite(pts), axis=1) & np.all(np.abs(pts) < 1e5, axis=1)
    if present is not None:
        ok &= np.asarray(present, bool)
    size = max(canvas.shape[:2])
    thickness = max(1, round(size / 400))
    radius = max(2, round(size / 250))
    ints = np.round(np.where(ok[:, None], pts, 0)).astype(int)
    colours = joint_colours_ or joint_colours(len(pts))
    for a, b in limbs:
        if ok[a] and ok[b]:
            c = colour or colours[b]
            cv2.line(canvas, tuple(ints[a]), tuple(ints[b]), c, thickness, cv2.LINE_AA)
    for j in np.nonzero(ok)[0]:
        cv2.circle(canvas, tuple(ints[j]), radius, colour or colours[j], -1, cv2.LINE_AA)


def draw_poses(frame: np.ndarray, poses: np.ndarray, limbs: tuple[tuple[int, int], ...],
               ids: np.ndarray | None = None) -> np.ndarray:
    """Draw ``(n, J, 3)`` poses ``(x, y, score)`` on a copy of ``frame``.

    Joints with score 0 are left out. With ``ids`` each skeleton takes its id's colour,
    else the grey of detections.
    """
    canvas = np.ascontiguousarray(frame).copy()
    for i, pose in enumerate(poses):
        colour = id_colour(int(ids[i])) if ids is not None else DETECTION_COLOUR
        draw_skeleton(canvas, pose[:, :2], limbs, present=pose[:, 2] > 0, colour=colour)
    return canvas
