"""Point tracking on TAP-Vid (DAVIS, RGB-Stacking, Kinetics) and RoboTAP."""

from __future__ import annotations

import os
from typing import Any

import cv2
import numpy as np
from gymnasium import spaces
from typing_extensions import Unpack

from unitrack_env import spaces as ut_spaces
from unitrack_env.benchmarks.tapvid import TAPVidBenchmark
from unitrack_env.datasets.tapvid import PointVideo
from unitrack_env.envs.base import EpisodeOptions, SequenceEnv
from unitrack_env.errors import InvalidActionError
from unitrack_env.metrics.point_queries import episode_schedule
from unitrack_env.metrics.points import frame_reward
from unitrack_env.render import joint_colours

#: Default capacity of the padded query arrays (``max_queries``).
DEFAULT_MAX_QUERIES = 1024
#: Frames per second of each data set's videos where known (DAVIS is shot at 24 fps, the
#: Kinetics clips are resampled to 25 fps); the other pickles do not state it: None.
FRAME_RATES: dict[str, int | None] = {"TAPVid-DAVIS": 24, "TAPVid-RGBStacking": None,
                                      "RoboTAP": None, "TAPVid-Kinetics": 25}


class _InMemoryFrames:
    """The frame "decoder" of a video held in memory (the pickle's arrays): nothing to stop."""

    def close(self) -> None:
        """Nothing to release."""


class TAPVidEnv(SequenceEnv[PointVideo]):
    """Tracking any point: answer where every queried point is, and whether it is occluded.

    ## Description
    Each episode is one video of a TAP-Vid data set (Doersch et al., NeurIPS 2022): DAVIS
    (``tapvid_davis.pkl``), RGB-Stacking (``tapvid_rgb_stacking.pkl``) or RoboTAP
    (``robotap_split*.pkl``), read from the official pickles through a restricted unpickler
    (only numpy arrays, dtypes and scalars; anything else is refused naming the file and the
    global), or TAP-Vid-Kinetics: the official ``tapvid_kinetics.csv`` of point tracks with
    the Kinetics-700-2020 validation clips the user downloads
    (``{youtube_id}_{start:06}_{end:06}.mp4`` in any sub-folder of ``video_root``), decoded
    with OpenCV (this build reads H.264, HEVC, VP9, AV1 and MPEG-4 Part 2) and brought to
    25 fps and 250 frames as the reference's ``generate_tapvid.py`` does
    (:mod:`unitrack_env.datasets.tapvid_kinetics`). The queries are sampled as the
    reference samples them (``query_mode``): ``"first"``, one query per track at its first
    visible frame; ``"strided"``, every 5th frame, one query per track visible there, in
    track order.

    The episode is causal: a query is revealed at its own frame, and the agent then answers
    it in every later frame. ``"strided"`` queries are also scored on the frames *before*
    their query frame; an online agent answers those in a **second, time-reversed pass**:
    after the forward pass, the episode plays the frames again from the last query frame down
    to frame 0 (``observation["reverse"] == 1``, ``info["reverse"]``), revealing each query
    again at its frame, and the agent answers the frames before it. No agent is scored on a
    frame it has not been shown after the query's frame in playing order. A forward pass
    scores frames ``t >= q`` (``t = q`` is never scored), the reversed pass frames ``t < q``.
    Both modes score exactly the (query, frame) pairs the reference scores, so the numbers
    are comparable with published ones; the trackers behind those saw whole videos at once
    (offline), which an online agent here never does.

    With no ``root`` (and no ``UNITRACK_DATA``), a small deterministic synthetic data set in
    the same pickle layout is generated once into the user cache: textured objects crossing
    and passing behind an occluder, points fixed on their texture and on the background,
    with exact tracks; a point is occluded when the pixel under it shows another object or
    it is outside the frame. For Kinetics the synthetic default is the CSV and two short
    MPEG-4 clips written with OpenCV (``mp4v``; this cv2 has no H.264 encoder). No real
    Kinetics clip ships with this project: its only test data are these synthetic clips.

    Which setting matches which published table: the tables of the TAP-Vid paper and of
    the trackers evaluated on it (TAPIR, CoTracker, BootsTAP, ...) are measured on the
    256 x 256 raster, ``resolution="256"`` (the default); their column or caption names the
    query sampling ("first" or "strided"), which is ``query_mode``. A number measured with
    ``resolution="full"`` (each video's stored size, where pixel thresholds are tighter in
    relative terms) is not comparable with them.

    ## Observation space
    A ``Dict``:

    - ``frame``: :class:`~unitrack_env.spaces.Image`, uint8 RGB at the evaluation raster
      (256 x 256, or the stored size with ``resolution="full"``).
    - ``query_ids``: ``Box((max_queries,), int64)``, the ids of the queries revealed at this
      frame (an id indexes the action's rows), ``-1`` past ``num_new``.
    - ``query_points``: ``Box((max_queries, 2), float32)``, their positions ``(x, y)`` in
      raster pixels (``x = 0`` is the left edge of the frame; a pixel's centre is at
      ``i + 0.5``).
    - ``num_new``: ``Discrete(max_queries + 1)``, how many rows of the two above are used.
    - ``active``: ``MultiBinary(max_queries)``, the queries whose answer is recorded at this
      frame.
    - ``reverse``: ``Discrete(2)``, 1 in the time-reversed pass.

    ## Action space
    A ``Dict``: ``tracks`` ``Box((max_queries, 2), float32)``, each query's ``(x, y)`` in
    raster pixels, and ``occluded`` ``MultiBinary(max_queries)`` (1: not visible). Rows of
    queries not active are ignored; arrays of the episode's own query count (``num_queries``
    in the reset info) are accepted too. A wrong shape, or a NaN/infinite or out-of-bounds
    position of an active query, raises ``InvalidActionError`` before anything is recorded.

    ## Rewards
    The frame's ``<δ^x_avg``: over the active queries scored at this frame and visible in
    the ground truth, the fraction within 1, 2, 4, 8, 16 pixels, averaged (0 when none).

    ## Starting state
    ``reset`` returns frame 0 with the queries starting there. ``info`` holds ``sequence``,
    ``frame_index``, ``reverse``, ``seq_length`` (steps, both passes), ``frame_rate`` (24
    for DAVIS; None where the data set does not state it), ``num_frames``,
    ``num_queries``, ``query_mode``, ``raster_size`` ``(width, height)``, ``image_size``
    ``(height, width)``, ``synthetic``.

    ## Episode end
    ``terminated=True`` after the last step. ``info["metrics"]`` holds the TAP-Vid metrics
    of the video (:mod:`unitrack_env.metrics.points`): ``AJ``, ``delta_x_avg``, ``OA`` and
    ``Jaccard@d``, ``delta_x@d`` for d = 1, 2, 4, 8, 16, as fractions. Results are written
    per video as ``<folder>/<video>.npz`` with ``query_points`` (Q, 3) (t, y, x), ``tracks``
    (Q, T, 2) (x, y) and ``occluded`` (Q, T), in raster pixels and the reference's query
    order, rescorable by any outside script; a data set's score is the mean over videos. In
    ``"first"`` mode, frames before a query are never answered: the file holds the query
    position there, flagged occluded.

    ## Arguments
    - ``root``: a folder holding the data set's pickle(s), or a ``.pkl`` file; for Kinetics
      the folder of ``tapvid_kinetics.csv`` or that file (default: ``$UNITRACK_DATA/TAPVid``
      (``RoboTAP`` for RoboTAP, ``TAPVid-Kinetics`` for Kinetics), else the synthetic data).
    - ``benchmark``: ``"TAPVid-DAVIS"``, ``"TAPVid-RGBStacking"``, ``"TAPVid-Kinetics"`` or
      ``"RoboTAP"`` (set by the id).
    - ``video_root`` (Kinetics): the folder searched at any depth for the clips (default:
      the CSV's folder).
    - ``missing_clips`` (Kinetics): ``"error"`` (default: a clip not found is refused at
      construction, naming the path expected) or ``"skip"`` (play the clips found, as the
      authors advise since Kinetics videos get taken down; the dataset's ``missing`` lists
      the others). A clip OpenCV cannot decode, one longer than its segment by more than
      1 s (untrimmed), or one that ends more than 2 frames before an annotated visible point
      is refused when its episode is reset, before its first frame.
    - ``query_mode``: ``"first"`` (default) or ``"strided"``.
    - ``resolution``: ``"256"`` (default) or ``"full"``.
    - ``sequences``: restrict to these video names.
    - ``max_queries``: capacity of the query arrays (default 1024); a video with more
      queries is refused at reset, naming it.
    - ``max_frame_size``, ``decode_frames``, ``shuffle``, ``render_mode`` as every env;
      ``"rgb_array"`` draws each active query's answer (a filled dot: visible, a ring:
      occluded), one colour per query.

    ## Version history
    - v0: initial version (TAPVid-Kinetics-v0 added later, same version).
    """

    frame_size_source = "the evaluation raster"

    def __init__(
        self,
        root: str | os.PathLike | None = None,
        benchmark: str = "TAPVid-DAVIS",
        query_mode: str = "first",
        resolution: str = "256",
        sequences: list[str] | tuple[str, ...] | None = None,
        max_queries: int = DEFAULT_MAX_QUERIES,
        video_root: str | os.PathLike | None = None,
        missing_clips: str = "error",
        **options: Unpack[EpisodeOptions],
    ) -> None:
        options.setdefault("prefetch", False)  # frames are in memory already
        super().__init__(**options)
        bench = TAPVidBenchmark.build(root, benchmark, query_mode, str(resolution),
                                      video_root, missing_clips)
        self._use_benchmark(bench, sequences, bench.dataset.root)
        self.query_mode = bench.query_mode
        self.max_queries = int(max_queries)
        if self.max_queries < 1:
            raise ValueError(f"max_queries must be >= 1, got {max_queries}")
        cap, bound = self.max_queries, ut_spaces.COORD_MAX
        self.observation_space = spaces.Dict({
            "frame": ut_spaces.Image(*self.max_frame_size),
            "query_ids": spaces.Box(-1, cap - 1, (cap,), np.int64),
            "query_points": spaces.Box(-bound, bound, (cap, 2), np.float32),
            "num_new": spaces.Discrete(cap + 1),
            "active": spaces.MultiBinary(cap),
            "reverse": spaces.Discrete(2),
        })
        self.action_space = spaces.Dict({
            "tracks": spaces.Box(-bound, bound, (cap, 2), np.float32),
            "occluded": spaces.MultiBinary(cap),
        })

    # ------------------------------------------------------------------ episode hooks
    def _load(self, name: str) -> dict[str, Any]:
        video = self.scoring.load(name)
        queries = self.scoring.queries(name)
        if len(queries) > self.max_queries:
            raise ValueError(f"{name}: {len(queries)} queries ({self.query_mode}) exceed "
                             f"max_queries={self.max_queries}; pass a larger max_queries")
        width, height = self.scoring.raster(name)
        self._check_frame_size(name, width, height, axes=False)
        self._sequence, self._queries = video, queries
        self._raster = (width, height)
        self._schedule = episode_schedule(video.num_frames, queries.query_frames,
                                          self.query_mode)
        self._cache: dict[int, np.ndarray] = {}
        frames = video.num_frames
        start = queries.query_points[:, [2, 1]]
        self._tracks = np.repeat(start[:, None, :], frames, axis=1)
        self._occluded = np.ones((len(queries), frames), bool)
        return dict(seq_length=len(self._schedule), num_frames=frames,
                    frame_rate=FRAME_RATES[self.dataset.benchmark],
                    num_queries=len(queries), query_mode=self.query_mode,
                    raster_size=(width, height), image_size=(height, width),
                    synthetic=self.synthetic, has_ground_truth=True)

    def _length(self) -> int:
        return len(self._schedule)

    def _open_frames(self, path_of: Any, keys: Any, *, prefetch: bool) -> Any:
        return _InMemoryFrames()

    def sequence_inputs(self, name: str) -> list[Any]:
        """The files of video ``name``: its pickle (Kinetics: the CSV and the clip)."""
        return self.dataset.inputs_of(name)

    def _frame_info(self, t: int) -> dict[str, Any]:
        frame, reverse = self._schedule[t]
        return {"frame_index": frame, "reverse": reverse}

    def _read_frame(self, t: int) -> np.ndarray:
        frame = self._schedule[t][0]
        if not self.decode_frames:
            self._frame = np.zeros((1, 1, 3), np.uint8)
        else:
            if frame not in self._cache:
                image = self._sequence.frames[frame]
                if image.shape[1::-1] != self._raster:
                    shrink = image.shape[1] > self._raster[0]
                    image = cv2.resize(image, self._raster, interpolation=cv2.INTER_AREA
                                       if shrink else cv2.INTER_LINEAR)
                self._cache[frame] = image
            self._frame = self._cache[frame]
        return self._frame

    def _active(self, t: int) -> np.ndarray:
        frame, reverse = self._schedule[t]
        q = self._queries.query_frames
        return q > frame if reverse else q <= frame

    def _observe(self, t: int) -> dict[str, Any]:
        frame, reverse = self._schedule[t]
        q = self._queries.query_frames
        new = np.flatnonzero((q == frame) & (q > 0 if reverse else True))
        cap = self.max_queries
        ids = np.full(cap, -1, np.int64)
        points = np.zeros((cap, 2), np.float32)
        ids[:len(new)] = new
        points[:len(new)] = self._queries.query_points[new][:, [2, 1]]
        active = np.zeros(cap, np.int8)
        active[:len(q)] = self._active(t)
        return {"frame": self._read_frame(t).copy(), "query_ids": ids, "query_points": points,
                "num_new": len(new), "active": active, "reverse": int(reverse)}

    def _record(self, action: Any, t: int) -> tuple[float, dict[str, Any]]:
        """Record the active queries' answers; the reward is the frame's ``<δ^x_avg``."""
        active = self._active(t)
        tracks, occluded = _validate_points(action, len(self._queries), self.max_queries,
                                            active)
        frame, reverse = self._schedule[t]
        self._tracks[active, frame] = tracks[active]
        self._occluded[active, frame] = occluded[active]
        self._answer = (frame, active)
        scored = active & (self._queries.query_frames != frame)
        reward = frame_reward(tracks[scored], occluded[scored],
                              self._queries.tracks[scored, frame],
                              self._queries.occluded[scored, frame])
        return reward, {}

    # ------------------------------------------------------------------ results
    def episode_results(self) -> dict[str, np.ndarray]:
        """``query_points``, ``tracks`` and ``occluded`` of the episode so far (raster px)."""
        if self._sequence is None:
            return {"query_points": np.zeros((0, 3)), "tracks": np.zeros((0, 0, 2)),
                    "occluded": np.zeros((0, 0), bool)}
        return {"query_points": self._queries.query_points.copy(),
                "tracks": self._tracks.copy(), "occluded": self._occluded.copy()}

    # ------------------------------------------------------------------ rendering
    def _draw(self) -> np.ndarray:
        """The frame with each active query's last answer (ring: predicted occluded)."""
        canvas = np.ascontiguousarray(self._frame).copy()
        if self._answer is None:
            return canvas
        frame, active = self._answer
        colours = joint_colours(max(len(active), 1))
        radius = max(2, round(max(canvas.shape[:2]) / 128))
        for k in np.flatnonzero(active):
            x, y = self._tracks[k, frame]
            if abs(x) > 1e5 or abs(y) > 1e5:
                continue
            centre = (int(round(x - 0.5)), int(round(y - 0.5)))
            cv2.circle(canvas, centre, radius, colours[k], 1 if self._occluded[k, frame] else -1,
                       cv2.LINE_AA)
        return canvas


def _validate_points(action: Any, count: int, capacity: int, active: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The action's ``(count, 2)`` positions and ``(count,)`` flags, or InvalidActionError."""
    if not isinstance(action, dict) or "tracks" not in action or "occluded" not in action:
        raise InvalidActionError("action must be a dict with 'tracks' (x, y per query) and "
                                 "'occluded' (a flag per query)")
    tracks, occluded = np.asarray(action["tracks"]), np.asarray(action["occluded"])
    rows = tracks.shape[0] if tracks.ndim == 2 else -1
    if tracks.ndim != 2 or tracks.shape[1] != 2 or rows not in (count, capacity):
        raise InvalidActionError(f"tracks must be ({capacity}, 2) or ({count}, 2) positions "
                                 f"(x, y); got shape {tracks.shape}")
    if occluded.shape != (rows,):
        raise InvalidActionError(f"occluded must be ({rows},) flags; got shape "
                                 f"{occluded.shape}")
    if not (np.issubdtype(tracks.dtype, np.number) and (np.issubdtype(occluded.dtype, np.number)
                                                         or occluded.dtype == np.bool_)):
        raise InvalidActionError(f"tracks and occluded must hold numbers, got {tracks.dtype} "
                                 f"and {occluded.dtype}")
    tracks = tracks[:count].astype(np.float64)
    occluded = occluded[:count].astype(np.float64)
    bad = active & ~(np.isfinite(tracks).all(axis=1) & np.isfinite(occluded)
                     & (np.abs(tracks) <= ut_spaces.COORD_MAX).all(axis=1))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise InvalidActionError(
            f"query {k}: position {tracks[k].tolist()} / flag {occluded[k]} must be finite "
            f"and within [-{ut_spaces.COORD_MAX:g}, {ut_spaces.COORD_MAX:g}] pixels")
    return tracks, occluded >= 0.5
