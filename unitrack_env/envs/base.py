"""What every unitrack environment shares: episodes over the sequences of a data set.

An episode is one sequence: ``reset(options={"sequence": name})`` picks one; otherwise the
split is walked in order (or a seeded shuffle), and ``seed`` restarts the walk.
:class:`SequenceEnv` owns the loop; a task environment supplies a few hooks.
"""

from __future__ import annotations

import abc
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, ClassVar, Generic, TypedDict, TypeVar

import gymnasium as gym
import numpy as np

from unitrack_env.benchmarks.base import Benchmark, select_sequences
from unitrack_env.dependencies import require
from unitrack_env.errors import DataFormatError, InvalidActionError, UnknownSequenceError
from unitrack_env.fingerprint import sequence_files
from unitrack_env.frames import FramePrefetcher
from unitrack_env.metrics.report import ScoreReport

#: Default bound of the frame space (height, width): 4K.
DEFAULT_MAX_FRAME_SIZE = (2160, 3840)

#: The sequence type of an environment (``MOTSequence``, ``VOSSequence``, ...).
SequenceT = TypeVar("SequenceT")


class EpisodeOptions(TypedDict, total=False):
    """The keyword arguments every environment takes besides its data set's own.

    - ``max_frame_size``: bound ``(height, width)`` of the frame space.
    - ``decode_frames``: when False, ``frame`` is a 1x1 black placeholder (saves decoding).
    - ``prefetch``: decode the next frame on a background thread.
    - ``shuffle``: visit sequences in a seeded random order.
    - ``render_mode``: None or ``"rgb_array"``.
    """

    max_frame_size: tuple[int, int]
    decode_frames: bool
    prefetch: bool
    shuffle: bool
    render_mode: str | None


class SequenceEnv(gym.Env, Generic[SequenceT], metaclass=abc.ABCMeta):
    """Base class: the episode loop over the sequences of a data set (a template method).

    :meth:`reset` picks a sequence, has :meth:`_load` read and check it, opens the frame decoder
    and returns :meth:`_observe`'s observation. :meth:`step` lets :meth:`_record` check, record
    and score the action, then moves to the next frame or ends the episode with
    ``info["metrics"]`` (when there is ground truth). The cursor :attr:`_t` runs over
    ``_first_step() .. _first_step() + _length() - 1``.

    A task environment sets :attr:`sequence_names`, its spaces and :attr:`scoring` (its
    :class:`~unitrack_env.benchmarks.base.Benchmark`) in ``__init__``; implements
    :meth:`_load`, :meth:`_observe`, :meth:`_record`, :meth:`_draw` and
    :meth:`episode_results`; and overrides :meth:`_length`, :meth:`_frame_path` and
    :meth:`_frame_size` unless its sequences have ``frame_paths`` and ``image_size``. The
    results contract ``evaluation`` relies on delegates to :attr:`scoring`.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 30}

    sequence_names: list[str]

    #: Frame decoder of the current episode (opened by :meth:`reset`; :meth:`close` stops it).
    _frames: FramePrefetcher | None = None
    #: The sequence of the current episode (None before the first reset).
    _sequence: SequenceT | None = None
    #: Decode frames (False: observations carry a 1x1 black placeholder instead).
    decode_frames: bool = True
    #: The task's benchmark (set in ``__init__``): ground truth, the official result format,
    #: scoring. The results contract below delegates to it.
    scoring: Benchmark

    #: Import names of the runtime dependencies this environment's scoring needs, checked
    #: when it is made (:func:`unitrack_env.dependencies.require`).
    requires: ClassVar[tuple[str, ...]] = ()

    #: The bound ``(height, width)`` of the frame space when ``max_frame_size`` is not given.
    default_max_frame_size: ClassVar[tuple[int, int]] = DEFAULT_MAX_FRAME_SIZE

    #: What states the frame size that decoded frames are checked against (named in the
    #: error of a frame of another size).
    frame_size_source: ClassVar[str] = "the sequence's first frame"

    def __init__(self, *, max_frame_size: tuple[int, int] | None = None,
                 decode_frames: bool = True, prefetch: bool = True, shuffle: bool = False,
                 render_mode: str | None = None) -> None:
        for module in self.requires:
            require(module, f"{type(self).__name__} (official scoring)")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode={render_mode!r} is not supported; use one of "
                f"{self.metadata['render_modes']} or None"
            )
        self.render_mode = render_mode
        self.shuffle = shuffle
        self._order: list[str] | None = None
        self._cursor = 0
        size = self.default_max_frame_size if max_frame_size is None else max_frame_size
        self.max_frame_size = (int(size[0]), int(size[1]))
        self.decode_frames = decode_frames
        self.prefetch = prefetch
        self._sequence = None
        self._frames = None
        self._t = self._stop = 0  # the cursor and the end of the episode's frame keys
        self._done, self._has_gt, self._closed = True, False, False
        self._frame: np.ndarray | None = None
        self._observation: dict[str, Any] = {}
        #: The agent's last answer as the renderer draws it (set by _record; None at reset)
        #: and the frame it answered.
        self._answer: Any = None
        self._answer_frame: np.ndarray | None = None

    def _use_benchmark(self, benchmark: Benchmark, sequences: Iterable[str] | None,
                       where: object) -> None:
        """Play ``benchmark``'s data set (:attr:`dataset`): ``sequences`` of it, None for all."""
        self.scoring = benchmark
        self.dataset = benchmark.dataset
        self.sequence_names = select_sequences(sequences, self.dataset.sequence_names, where)

    def close(self) -> None:
        """Stop the frame prefetching thread (if any) and end the episode: reset() next."""
        if self._frames is not None:
            self._frames.close()
        self._done = self._closed = True
        super().close()

    def _choose_sequence(self, seed: int | None, options: dict[str, Any] | None) -> str:
        options = options or {}
        unknown = set(options) - {"sequence"}
        if unknown:
            raise ValueError(f"unknown reset option(s) {sorted(unknown)}; valid: ['sequence']")
        if seed is not None or self._order is None:
            self._order = list(self.sequence_names)
            if self.shuffle:
                self._order = [self._order[i] for i in self.np_random.permutation(len(self._order))]
            self._cursor = 0
        if options.get("sequence") is not None:
            name = str(options["sequence"])
            if name not in self.sequence_names:
                raise UnknownSequenceError(
                    f"no sequence '{name}'; this environment has: {', '.join(self.sequence_names)}"
                )
            return name
        name = self._order[self._cursor % len(self._order)]
        self._cursor += 1
        return name

    # ------------------------------------------------------------------ episode loop
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Start an episode on one sequence (see the class docstring)."""
        super().reset(seed=seed)
        name = self._choose_sequence(seed, options)
        if self._frames is not None:
            self._frames.close()
        self._done = True
        extras = self._load(name)
        self._has_gt = bool(extras["has_ground_truth"])
        self._answer = self._answer_frame = None
        first = self._first_step()
        self._stop = first + self._length()
        self._frames = self._open_frames(self._frame_path, range(first, self._stop),
                                         prefetch=self.prefetch)
        self._t = first
        self._done = self._closed = False
        observation = self._observation = self._observe(first)
        info = self._step_info(first) | extras
        return observation, {**info, "task": self.task, "capacities": self.capacities()}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """Record the agent's answer for the current frame, score it, and move on."""
        if self._done or self._sequence is None:
            state = ("before any reset()" if self._sequence is None else
                     "after close()" if self._closed else "on a finished episode")
            raise RuntimeError(f"step() called {state}; call reset() to start an episode")
        t = self._t
        try:
            reward, extra = self._record(action, t)
        except InvalidActionError as exc:  # say which frame: the agent's bug may be rare
            raise InvalidActionError(f"frame {self._frame_info(t)['frame_index']}: {exc}") \
                from None
        self._answer_frame = self._frame
        if t + 1 >= self._stop:
            self._done = True
            observation = {key: self._fresh(value) if isinstance(value, np.ndarray) else value
                           for key, value in self._observation.items()}
            info = self._step_info(t) | extra
            if self._has_gt:
                info["metrics"] = self.episode_metrics()
            if self._frames is not None:
                self._frames.close()
            return observation, reward, True, False, info
        self._t = t + 1
        observation = self._observation = self._observe(self._t)
        return observation, reward, False, False, self._step_info(self._t) | extra

    def _step_info(self, t: int) -> dict[str, Any]:
        return {"sequence": self._sequence.name, **self._frame_info(t)}

    def _frame_info(self, t: int) -> dict[str, Any]:
        """The info keys that name frame ``t``: ``frame_index`` (default: ``t``) and extras."""
        return {"frame_index": t}

    def _first_step(self) -> int:
        """The cursor of the first frame (default 0; e.g. 1 for 1-based frame numbers)."""
        return 0

    @abc.abstractmethod
    def _load(self, name: str) -> dict[str, Any]:
        """Read and check sequence ``name``; return reset-info extras incl. ``has_ground_truth``."""

    # The next three hooks read a sequence that lists its frames as ``frame_paths`` (one
    # file per step) with ``image_size`` = ``(width, height)``, as the DAVIS, OTB, JHMDB
    # and PoseTrack readers do; environments whose sequences differ override them.
    def _length(self) -> int:
        """The number of frames (steps) of the current episode."""
        return len(self._sequence.frame_paths)

    def _frame_path(self, t: int) -> Path:
        """The image file of frame ``t`` of the current episode."""
        return self._sequence.frame_paths[t]

    def _frame_size(self) -> tuple[int, int]:
        """The ``(width, height)`` the current sequence's frames must have."""
        return self._sequence.image_size

    @abc.abstractmethod
    def _observe(self, t: int) -> dict[str, Any]:
        """The observation of frame ``t`` (read its image with :meth:`_read_frame`)."""

    @abc.abstractmethod
    def _record(self, action: Any, t: int) -> tuple[float, dict[str, Any]]:
        """Check (``InvalidActionError`` before recording), record and score frame ``t``'s action.

        Sets :attr:`_answer` for :meth:`_draw`; returns the reward and the info keys it adds.
        """

    @property
    def task(self) -> str:
        """The task family (its benchmark's), as :func:`unitrack_env.task_of` names it.

        Reset infos carry it as ``info["task"]``, with the action capacities as
        ``info["capacities"]``.
        """
        return self.scoring.task

    @property
    def synthetic(self) -> bool:
        """Whether the data set is the embedded synthetic default."""
        return self.scoring.synthetic

    def capacities(self) -> dict[str, int]:
        """The environment's size limits (its ``max_*`` settings, e.g. ``max_tracks``)."""
        return {key: value for key, value in sorted(vars(self).items())
                if key.startswith("max_") and isinstance(value, int)}

    @property
    def sequence(self) -> SequenceT | None:
        """The sequence of the current episode (None before the first reset)."""
        return self._sequence

    def render(self) -> np.ndarray | None:
        """The ``rgb_array`` picture of the current state (None without a render mode)."""
        if self.render_mode is None:
            return None
        if self._sequence is None:
            raise RuntimeError("call reset() before render()")
        return self._draw()

    @abc.abstractmethod
    def _draw(self) -> np.ndarray:
        """The ``rgb_array`` picture of the current state."""

    # ------------------------------------------------------------------ frames
    def _check_frame_size(self, name: str, width: int, height: int, *, axes: bool = True,
                          hint: str = "max_frame_size") -> None:
        """Refuse a sequence whose frames exceed ``max_frame_size`` (height, width)."""
        if height > self.max_frame_size[0] or width > self.max_frame_size[1]:
            raise ValueError(
                f"{name}: frames are {width}x{height}, larger than max_frame_size="
                f"{self.max_frame_size}{' (height, width)' if axes else ''}; pass a larger {hint}"
            )

    def _open_frames(self, path_of: Callable[[int], Path], keys: Iterable[int], *,
                     prefetch: bool) -> FramePrefetcher:
        """The frame decoder of a new episode, after checking every frame file is complete.

        A truncated JPEG decodes to a flat colour without an error, so it is refused at reset.
        """
        frames = FramePrefetcher(path_of, prefetch=prefetch)
        if self.decode_frames:
            frames.check(keys)
        return frames

    def _read_frame(self, t: int) -> np.ndarray:
        """Decode frame ``t`` (kept as :attr:`_frame`), check its size, schedule the next."""
        if not self.decode_frames:
            self._frame = np.zeros((1, 1, 3), dtype=np.uint8)
            return self._frame
        image = self._frames.get(t)
        if t + 1 < self._stop:
            self._frames.schedule(t + 1)
        size = self._frame_size()
        if image.shape[1::-1] != tuple(size):
            raise DataFormatError(self._frame_path(t), f"image is {image.shape[1]}x"
                                  f"{image.shape[0]} but {self.frame_size_source} says "
                                  f"{size[0]}x{size[1]}")
        self._frame = image
        return image

    # ----------------------------------------------------------- results contract
    def sequence_inputs(self, name: str) -> list[Path]:
        """The files sequence ``name`` is read from, fingerprinted so a resumed run replays changes.

        The default takes the data set's files of the sequence; environments reading files from
        elsewhere (e.g. user detections) add them.
        """
        root = self.inputs_root()
        if root is None:
            return []
        names = getattr(self.dataset, "sequence_names", self.sequence_names)
        return sequence_files(root, name, names)

    def inputs_root(self) -> Path | None:
        """The data set's folder, or None without one.

        Fingerprints name the input files relative to it, so the same data in another
        folder resumes a run.
        """
        dataset = getattr(self, "dataset", None)
        root = getattr(dataset, "root", None) or getattr(dataset, "data_dir", None)
        return None if root is None else Path(root)

    def sequence_length(self, name: str) -> int:
        """Number of frames (steps) of sequence ``name``, without loading it."""
        return self.scoring.sequence_length(name)

    def has_ground_truth(self, name: str) -> bool:
        """Whether sequence ``name`` can be scored."""
        return self.scoring.has_ground_truth(name)

    @abc.abstractmethod
    def episode_results(self) -> Any:
        """The results recorded so far, in the form :attr:`scoring` writes and scores."""

    def episode_digest(self) -> str:
        """A stable digest of the actions recorded in the current episode."""
        return self.scoring.digest(self.episode_results())

    def episode_metrics(self) -> dict[str, float]:
        """The official metrics of the recorded episode (:attr:`scoring`'s ``score_sequence``).

        Raises:
            ValueError: the sequence has no ground truth.
        """
        if self._sequence is None or not self._has_gt:
            raise ValueError("this sequence has no ground truth to score against")
        return self.scoring.score_sequence(self._sequence.name, self.episode_results())

    def write_episode(self, folder: Path) -> None:
        """Write the current (finished) episode's results in the official format.

        Writes are atomic (``unitrack_env.io``) so an interrupted run never leaves half a
        result behind.
        """
        self._require_episode()
        self.scoring.write(folder, self._sequence.name, self.episode_results())

    def score_folder(self, folder: Path, sequences: list[str]) -> ScoreReport:
        """Score results written by :meth:`write_episode` with the official metrics."""
        return self.scoring.score_folder(folder, sequences)

    def _require_episode(self, played: bool = True) -> None:
        """Refuse to write results before an episode was played (``played``: it was)."""
        if self._sequence is None or not played:
            raise RuntimeError("no episode to write; call reset() and play it first")

    @staticmethod
    def _fresh(array: np.ndarray) -> np.ndarray:
        return np.array(array, copy=True)
