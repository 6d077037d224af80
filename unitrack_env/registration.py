"""The table of registered environments.

``import unitrack_env`` registers these ids (Gymnasium 1.x has no plugin discovery). Each row:
name, entry point, default arguments, data folder and ``scoring`` (the ``module:Class`` of its
:class:`~unitrack_env.benchmarks.base.Benchmark`). Other projects use :func:`register_variant`.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym

from unitrack_env.score_range import DETECTION_SCORES, ScoreRange

#: Namespace of every id.
NAMESPACE = "UniTrack"


@dataclass(frozen=True)
class Variant:
    """One registered environment id."""

    name: str
    entry_point: str
    kwargs: dict[str, Any] = field(default_factory=dict)
    version: int = 0
    #: The folder name under ``$UNITRACK_DATA`` that the id reads (None: ``root=`` only).
    folder: str | None = None
    #: The id's benchmark, ``"module:Class"`` of a :class:`unitrack_env.benchmarks.Benchmark`
    #: (built from the env's keyword arguments by :func:`unitrack_env.benchmarks.benchmark_for`).
    scoring: str = ""

    @property
    def scoring_class(self) -> type | None:
        """The class ``scoring`` names, imported (None: the row names none).

        :func:`unitrack_env.benchmarks.benchmark_class` checks that it is a Benchmark.
        """
        if not self.scoring:
            return None
        module, _, name = self.scoring.partition(":")
        return getattr(importlib.import_module(module), name, None)

    @property
    def task(self) -> str:
        """The task family, stated by the id's benchmark ("" for a row without one)."""
        return getattr(self.scoring_class, "task", "")

    @property
    def env_id(self) -> str:
        """The full Gymnasium id, e.g. ``UniTrack/MOT17-v0``."""
        return f"{NAMESPACE}/{self.name}-v{self.version}"

    @property
    def detection_scores(self) -> ScoreRange | None:
        """The declared range of the id's detection scores (None: no detections).

        Looked up in :data:`unitrack_env.score_range.DETECTION_SCORES` by the row's
        ``benchmark`` argument, else its folder.
        """
        return DETECTION_SCORES.get(self.kwargs.get("benchmark") or self.folder or "")


_MOT = "unitrack_env.envs.motchallenge:MOTChallengeEnv"
_B = "unitrack_env.benchmarks."
_MOT_SCORING = _B + "motchallenge:MOTChallengeBenchmark"
_TAPVID = "unitrack_env.envs.tapvid:TAPVidEnv"
_TAPVID_SCORING = _B + "tapvid:TAPVidBenchmark"

VARIANTS: tuple[Variant, ...] = (
    Variant("MOT15", _MOT, {"benchmark": "MOT15"}, folder="MOT15", scoring=_MOT_SCORING),
    Variant("MOT16", _MOT, {"benchmark": "MOT16"}, folder="MOT16", scoring=_MOT_SCORING),
    Variant("MOT17", _MOT, {"benchmark": "MOT17"}, folder="MOT17", scoring=_MOT_SCORING),
    Variant("MOT20", _MOT, {"benchmark": "MOT20"}, folder="MOT20", scoring=_MOT_SCORING),
    # No public detections: give detections= (or <root>/detections/<split>/); val by default.
    Variant("DanceTrack", _MOT, {"benchmark": "DanceTrack", "split": "val"},
            folder="DanceTrack", scoring=_B + "motchallenge:DanceTrackBenchmark"),
    Variant("SportsMOT", _MOT, {"benchmark": "SportsMOT", "split": "val"}, folder="SportsMOT",
            scoring=_MOT_SCORING),
    # Custom data in the MOTChallenge layout; pass root= and the benchmark= rule set.
    Variant("MOTChallenge", _MOT, {"benchmark": "MOT17"}, scoring=_MOT_SCORING),
    Variant("KITTI", "unitrack_env.envs.kitti:KITTIEnv", {}, folder="KITTI",
            scoring=_B + "kitti:KITTIBenchmark"),
    Variant("BDD100K", "unitrack_env.envs.bdd100k:BDD100KEnv", {}, folder="BDD100K",
            scoring=_B + "bdd100k:BDD100KBenchmark"),
    Variant("OTB", "unitrack_env.envs.otb:OTBEnv", {}, folder="OTB",
            scoring=_B + "otb:OTBBenchmark"),
    Variant("LaSOT", "unitrack_env.envs.otb:OTBEnv", {"data_format": "lasot"}, folder="LaSOT",
            scoring=_B + "otb:LaSOTBenchmark"),
    Variant("UAV123", "unitrack_env.envs.otb:OTBEnv", {"data_format": "uav123"},
            folder="UAV123", scoring=_B + "otb:SOTProtocolBenchmark"),
    Variant("GOT10k", "unitrack_env.envs.otb:OTBEnv", {"data_format": "got10k"},
            folder="GOT-10k", scoring=_B + "got10k:GOT10kBenchmark"),
    Variant("TrackingNet", "unitrack_env.envs.otb:OTBEnv", {"data_format": "trackingnet"},
            folder="TrackingNet", scoring=_B + "otb:SOTProtocolBenchmark"),
    Variant("NfS", "unitrack_env.envs.otb:OTBEnv", {"data_format": "nfs"}, folder="NfS",
            scoring=_B + "otb:OTBBenchmark"),
    Variant("DAVIS", "unitrack_env.envs.davis:DAVISEnv", {}, folder="DAVIS",
            scoring=_B + "davis:DAVISBenchmark"),
    Variant("MOTS", "unitrack_env.envs.mots:MOTSEnv", {"benchmark": "MOTS20"},
            folder="MOTS20", scoring=_B + "mots:MOTSBenchmark"),
    Variant("VIS", "unitrack_env.envs.vis:VISEnv", {}, folder="YouTube-VIS-2019",
            scoring=_B + "vis:VISBenchmark"),
    Variant("JHMDB", "unitrack_env.envs.jhmdb:JHMDBEnv", {}, folder="JHMDB",
            scoring=_B + "jhmdb:JHMDBBenchmark"),
    Variant("PoseTrack", "unitrack_env.envs.posetrack:PoseTrackEnv", {},
            folder="PoseTrack2018", scoring=_B + "posetrack:PoseTrackBenchmark"),
    Variant("TAPVid-DAVIS", _TAPVID, {"benchmark": "TAPVid-DAVIS"}, folder="TAPVid",
            scoring=_TAPVID_SCORING),
    Variant("TAPVid-RGBStacking", _TAPVID, {"benchmark": "TAPVid-RGBStacking"},
            folder="TAPVid", scoring=_TAPVID_SCORING),
    Variant("RoboTAP", _TAPVID, {"benchmark": "RoboTAP"}, folder="RoboTAP",
            scoring=_TAPVID_SCORING),
    Variant("TAPVid-Kinetics", _TAPVID, {"benchmark": "TAPVid-Kinetics"},
            folder="TAPVid-Kinetics", scoring=_TAPVID_SCORING),
)

#: Rows added at run time by :func:`register_variant` (a user's own tasks).
_ADDED: list[Variant] = []


def variants() -> tuple[Variant, ...]:
    """Every registered row: the built-in :data:`VARIANTS`, then those added at run time."""
    return (*VARIANTS, *_ADDED)


def register_variant(row: Variant) -> None:
    """Add a row to the table and register its id with Gymnasium (idempotent per id).

    How a project adds its own task without editing this package; a clashing id raises
    ValueError.
    """
    for known in variants():
        if known.env_id == row.env_id:
            if known == row:
                return
            raise ValueError(f"'{row.env_id}' is already registered (entry point "
                             f"{known.entry_point}); choose another name or version")
    _ADDED.append(row)
    _register(row)


def _register(row: Variant) -> None:
    if row.env_id not in gym.registry:
        gym.register(id=row.env_id, entry_point=row.entry_point, kwargs=dict(row.kwargs),
                     disable_env_checker=False)


def register_all() -> None:
    """Register every variant (idempotent)."""
    for row in variants():
        _register(row)


def env_ids(task: str | None = None) -> list[str]:
    """Return the registered ids, optionally only those of one task (e.g. ``"mot"``)."""
    return [v.env_id for v in variants() if task is None or v.task == task]


def task_of(env_id: str) -> str:
    """Return the task family of a registered id (``"mot"``, ...)."""
    return variant(env_id).task


def variant(env_id: str) -> Variant:
    """The registration row of ``env_id``."""
    for row in variants():
        if row.env_id == env_id:
            return row
    raise KeyError(f"'{env_id}' is not a unitrack id; registered: {', '.join(env_ids())}")
