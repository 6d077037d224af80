"""TAP-Vid query sampling and the evaluation raster (Doersch et al. 2022, section 4).

A *query* is one point to track: ``(t, y, x)``, a frame and a position where the point is
visible. The reference samples them two ways:

- ``"first"``: one query per track, at the track's first visible frame (tracks never
  visible give none), in track order;
- ``"strided"``: for every ``QUERY_STRIDE``-th frame ``q = 0, 5, 10, ...``, one query per
  track visible at ``q``, in track order (a track is asked about several times).

Coordinates are in pixels of the evaluation raster: the normalised points times the raster's
``(width, height)`` (256 x 256 in the published tables), so ``x = 0`` is the left edge of the
first pixel column and a pixel's centre is at ``i + 0.5``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

QUERY_MODES: tuple[str, ...] = ("first", "strided")
"""The reference's two query samplings."""

QUERY_STRIDE: int = 5
"""Frames between the query frames of ``"strided"`` sampling (the reference's)."""

EVAL_SIZE: tuple[int, int] = (256, 256)
"""``(width, height)`` of the raster the published tables are measured on."""


def check_query_mode(mode: str) -> str:
    """``mode`` if it is a query mode, else ValueError naming them."""
    if mode not in QUERY_MODES:
        raise ValueError(f"query_mode must be one of {QUERY_MODES}, got {mode!r}")
    return mode


def to_raster(points: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Normalised ``(..., 2)`` x, y points in pixels of a ``(width, height)`` raster (float64)."""
    return np.asarray(points, np.float64) * np.array([size[0], size[1]], np.float64)


@dataclass(frozen=True)
class PointQueries:
    """The queries of one video and their ground truth, in the sampling order.

    ``query_points`` ``(Q, 3)`` (t, y, x); ``tracks`` ``(Q, T, 2)`` x, y and ``occluded``
    ``(Q, T)`` of each query's track; ``track_index`` ``(Q,)`` the track each query asks about.
    """

    query_points: np.ndarray
    tracks: np.ndarray
    occluded: np.ndarray
    track_index: np.ndarray

    @property
    def query_frames(self) -> np.ndarray:
        """``(Q,)`` int frame of each query."""
        return self.query_points[:, 0].astype(np.int64)

    def __len__(self) -> int:
        return len(self.query_points)


def sample_queries(tracks: np.ndarray, occluded: np.ndarray, mode: str,
                   stride: int = QUERY_STRIDE) -> PointQueries:
    """Sample the queries of one video: ``tracks`` ``(N, T, 2)`` x, y and ``occluded`` ``(N, T)``.

    >>> occ = np.array([[True, False, False], [False, True, False]])
    >>> xy = np.arange(12, dtype=float).reshape(2, 3, 2)
    >>> sample_queries(xy, occ, "first").query_points.tolist()
    [[1.0, 3.0, 2.0], [0.0, 7.0, 6.0]]
    """
    check_query_mode(mode)
    tracks = np.asarray(tracks, np.float64)
    visible = ~np.asarray(occluded, bool)
    if mode == "first":
        pairs = [(int(np.argmax(visible[i])), i) for i in range(len(tracks)) if visible[i].any()]
    else:
        pairs = [(q, i) for q in range(0, visible.shape[1], stride)
                 for i in range(len(tracks)) if visible[i, q]]
    frames = np.array([q for q, _ in pairs], np.int64)
    index = np.array([i for _, i in pairs], np.int64)
    if not pairs:
        return PointQueries(np.zeros((0, 3)), np.zeros((0, visible.shape[1], 2)),
                            np.zeros((0, visible.shape[1]), bool), index)
    xy = tracks[index, frames]
    query_points = np.stack([frames.astype(np.float64), xy[:, 1], xy[:, 0]], axis=1)
    return PointQueries(query_points, tracks[index], ~visible[index], index)


def episode_schedule(num_frames: int, query_frames: np.ndarray, mode: str
                     ) -> list[tuple[int, bool]]:
    """The steps of an online episode: ``(frame, reverse)`` in playing order.

    A forward pass over every frame; in ``"strided"`` mode, when some query starts after
    frame 0, a second, time-reversed pass from the last query frame down to frame 0 answers
    the frames before each query (``"first"`` mode never scores those).

    >>> episode_schedule(3, np.array([0, 2]), "strided")
    [(0, False), (1, False), (2, False), (2, True), (1, True), (0, True)]
    """
    check_query_mode(mode)
    steps = [(t, False) for t in range(num_frames)]
    last = int(np.max(query_frames)) if len(query_frames) else 0
    if mode == "strided" and last > 0:
        steps += [(t, True) for t in range(last, -1, -1)]
    return steps
