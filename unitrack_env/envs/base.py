"""What every unitrack environment shares: episodes over the sequences of a data set.

An episode is one video sequence. ``reset(options={"sequence": name})`` picks a sequence;
without it the environment walks the split's sequences in order (or in a seeded shuffle with
``shuffle=True``). Passing ``seed`` restarts that walk, so the same seed gives the same
episode. Subclasses provide the data set, the observations and the scoring.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, ClassVar, Generic, TypeVar

import gymnasium as gym
import numpy as np

from unitrack_env.dependencies import require
from unitrack_env.errors import DataFormatError, UnknownSequenceError
from unitrack_env.fingerprint import sequence_files
from unitrack_env.frames import FramePrefetcher
from unitrack_env.metrics.report import ScoreReport

#: Environment variable naming a folder that holds benchmark folders (``MOT17/``, ``DAVIS/``,
#: ...); used when ``root`` is not given.
DATA_ENV_VAR = "UNITRACK_DATA"


class DataRootNotFound(DataFormatError):
    """The data folder that ``root=`` or ``$UNITRACK_DATA`` names does not exist."""


def resolve_root(root: str | os.PathLike | None, benchmark_folder: str) -> Path | None:
    """Return the data root to read, or None for the embedded synthetic default.

    ``root`` wins; otherwise ``$UNITRACK_DATA/<benchmark_folder>`` must exist when the
    variable is set (no silent fallback to synthetic data).
    """
    if root is not None:
        path = Path(root).expanduser()
        if not path.is_dir():
            raise DataRootNotFound(path, "root= is not a folder")
        return path
    base = os.environ.get(DATA_ENV_VAR)
    if base:
        path = Path(base).expanduser() / benchmark_folder
        if not path.is_dir():
            raise DataRootNotFound(
                path,
                f"{DATA_ENV_VAR}={base} is set but has no '{benchmark_folder}' folder; "
                f"unset it to use the embedded synthetic data, or pass root=",
            )
        return path
    return None


#: The sequence type of an environment (``MOTSequence``, ``VOSSequence``, ...).
SequenceT = TypeVar("SequenceT")


class SequenceEnv(gym.Env, Generic[SequenceT]):
    """Base class: sequence selection, seeding, episode bookkeeping and the render guard.

    Subclasses set :attr:`sequence_names` in ``__init__`` and implement
    :meth:`_start_episode` (which sets ``_sequence``), :meth:`_draw` (the ``rgb_array``
    picture of the current state), plus the results contract that ``evaluation`` relies on for every
    task: :meth:`sequence_length`, :meth:`has_ground_truth`, :meth:`episode_digest`,
    :meth:`write_episode` (official result format) and :meth:`score_folder` (official
    metrics of a folder of such results).
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 30}

    sequence_names: list[str]

    #: Frame decoder of the current episode (subclasses set it; :meth:`close` stops it).
    _frames: FramePrefetcher | None = None
    #: Whether the data set is the embedded synthetic default (set by :meth:`_data_root`).
    synthetic: bool = False
    #: The sequence of the current episode (None before the first reset).
    _sequence: SequenceT | None = None
    #: Decode frames (False: observations carry a 1x1 black placeholder instead).
    decode_frames: bool = True

    #: Import names of the runtime dependencies this environment's scoring needs, checked
    #: when it is made (:func:`unitrack_env.dependencies.require`).
    requires: ClassVar[tuple[str, ...]] = ()

    #: The task family this environment poses (``"mot"``, ``"vos"``, ...; see
    #: :func:`unitrack_env.task_of`), set by the ``task=`` class keyword. Reset infos carry it
    #: as ``info["task"]``, with the action capacities as ``info["capacities"]``.
    task: ClassVar[str] = ""

    def __init_subclass__(cls, task: str | None = None, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if task is not None:
            cls.task = task

    def __init__(self, *, shuffle: bool = False, render_mode: str | None = None) -> None:
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

    def _data_root(
        self, root: str | os.PathLike | None, folder: str, *synthetic_args: Any,
        **synthetic_kwargs: Any,
    ) -> Path:
        """The folder to read: ``root``, ``$UNITRACK_DATA/<folder>``, or the synthetic default.

        ``synthetic_args`` go to :func:`unitrack_env.datasets.synthetic.ensure_synthetic`
        (benchmark and kind) when the synthetic default is used; sets :attr:`synthetic`.
        """
        path = resolve_root(root, folder)
        self.synthetic = path is None
        if path is None:
            from unitrack_env.datasets.synthetic import ensure_synthetic

            path = ensure_synthetic(*synthetic_args, **synthetic_kwargs)
        return path

    @staticmethod
    def _select_sequences(
        requested: list[str] | tuple[str, ...] | None, available: list[str], where: object
    ) -> list[str]:
        """Validate a user's ``sequences=`` against the data set (None: all of them)."""
        if requested is None:
            return list(available)
        missing = [s for s in requested if s not in available]
        if missing:
            raise ValueError(
                f"sequences {missing} are not in {where}; available: {', '.join(available)}"
            )
        return list(requested)

    def close(self) -> None:
        """Stop the frame prefetching thread, if any."""
        if self._frames is not None:
            self._frames.close()
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

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Start an episode on one sequence (see the class docstring)."""
        super().reset(seed=seed)
        name = self._choose_sequence(seed, options)
        observation, info = self._start_episode(name)
        return observation, {**info, "task": self.task, "capacities": self.capacities()}

    def capacities(self) -> dict[str, int]:
        """The environment's size limits (its ``max_*`` settings, e.g. ``max_tracks``)."""
        return {key: value for key, value in sorted(vars(self).items())
                if key.startswith("max_") and isinstance(value, int)}

    def _start_episode(self, name: str) -> tuple[Any, dict[str, Any]]:
        raise NotImplementedError

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

    def _draw(self) -> np.ndarray:
        raise NotImplementedError

    def _open_frames(self, path_of: Callable[[int], Path], keys: Iterable[int], *,
                     prefetch: bool) -> FramePrefetcher:
        """The frame decoder of a new episode, after checking every frame file.

        Every frame in ``keys`` must exist and be complete (a truncated JPEG would decode to
        a flat colour without an error), so that a bad file is refused at reset, before a
        frame is played. Skipped when frames are not decoded.
        """
        frames = FramePrefetcher(path_of, prefetch=prefetch)
        if self.decode_frames:
            frames.check(keys)
        return frames

    def _decode(self, key: int, *, next_key: int | None, size: tuple[int, int],
                path: str | Path, source: str) -> np.ndarray:
        """Frame ``key`` of the prefetcher (a 1x1 black placeholder without decoding).

        Schedules ``next_key`` (None: the last frame) and checks the decoded size against
        ``size`` = ``(width, height)``, the size that ``source`` states (named in the error,
        e.g. ``"seqinfo.ini"``), raising :class:`DataFormatError` naming ``path``.
        """
        if not self.decode_frames:
            return np.zeros((1, 1, 3), dtype=np.uint8)
        image = self._frames.get(key)
        if next_key is not None:
            self._frames.schedule(next_key)
        if image.shape[1::-1] != tuple(size):
            raise DataFormatError(path, f"image is {image.shape[1]}x{image.shape[0]} but "
                                        f"{source} says {size[0]}x{size[1]}")
        return image

    # ----------------------------------------------------------- results contract
    def sequence_inputs(self, name: str) -> list[Path]:
        """The files that sequence ``name`` is read from (frames, annotations, detections).

        The runner fingerprints them (:mod:`unitrack_env.fingerprint`) so that a resumed run
        replays a sequence whose inputs changed. The default takes the files below the data
        set's folder that belong to the sequence; environments that read files from
        elsewhere (e.g. user detections) add them.
        """
        dataset = getattr(self, "dataset", None)
        root = getattr(dataset, "root", None) or getattr(dataset, "data_dir", None)
        if root is None:
            return []
        names = getattr(dataset, "sequence_names", self.sequence_names)
        return sequence_files(Path(root), name, names)

    def sequence_length(self, name: str) -> int:
        """Number of frames (steps) of sequence ``name``, without loading it."""
        raise NotImplementedError

    def has_ground_truth(self, name: str) -> bool:
        """Whether sequence ``name`` can be scored."""
        raise NotImplementedError

    def episode_digest(self) -> str:
        """A stable digest of the actions recorded in the current episode."""
        raise NotImplementedError

    def write_episode(self, folder: Path) -> None:
        """Write the current (finished) episode's results in the official format.

        Writes must be atomic (``unitrack_env.io``) so an interrupted run never leaves half a
        result behind.
        """
        raise NotImplementedError

    def score_folder(self, folder: Path, sequences: list[str]) -> ScoreReport:
        """Score results written by :meth:`write_episode` with the official metrics."""
        raise NotImplementedError

    @staticmethod
    def _fresh(array: np.ndarray) -> np.ndarray:
        return np.array(array, copy=True)
