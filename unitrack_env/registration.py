"""The table of registered environments.

Gymnasium 1.x has no plugin auto-discovery, so ``import unitrack_env`` registers these ids
(or use ``gym.make("unitrack_env:UniTrack/MOT16-v0")``, which imports the package first).
Each row is one id: ``(name, entry point, default keyword arguments, short description)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym

#: Namespace of every id.
NAMESPACE = "UniTrack"


@dataclass(frozen=True)
class Variant:
    """One registered environment id."""

    name: str
    entry_point: str
    kwargs: dict[str, Any] = field(default_factory=dict)
    task: str = ""
    version: int = 0
    #: The folder name under ``$UNITRACK_DATA`` that the id reads (None: ``root=`` only).
    folder: str | None = None

    @property
    def env_id(self) -> str:
        """The full Gymnasium id, e.g. ``UniTrack/MOT17-v0``."""
        return f"{NAMESPACE}/{self.name}-v{self.version}"


_MOT = "unitrack_env.envs.motchallenge:MOTChallengeEnv"

VARIANTS: tuple[Variant, ...] = (
    Variant("MOT15", _MOT, {"benchmark": "MOT15"}, "mot", folder="MOT15"),
    Variant("MOT16", _MOT, {"benchmark": "MOT16"}, "mot", folder="MOT16"),
    Variant("MOT17", _MOT, {"benchmark": "MOT17"}, "mot", folder="MOT17"),
    Variant("MOT20", _MOT, {"benchmark": "MOT20"}, "mot", folder="MOT20"),
    # Custom data in the MOTChallenge layout; pass root= and the benchmark= rule set.
    Variant("MOTChallenge", _MOT, {"benchmark": "MOT17"}, "mot"),
    Variant("OTB", "unitrack_env.envs.otb:OTBEnv", {}, "sot", folder="OTB"),
    Variant("DAVIS", "unitrack_env.envs.davis:DAVISEnv", {}, "vos", folder="DAVIS"),
    Variant("MOTS", "unitrack_env.envs.mots:MOTSEnv", {"benchmark": "MOTS20"}, "mots",
            folder="MOTS20"),
    Variant("VIS", "unitrack_env.envs.vis:VISEnv", {}, "vis", folder="YouTube-VIS-2019"),
    Variant("JHMDB", "unitrack_env.envs.jhmdb:JHMDBEnv", {}, "pose-prop", folder="JHMDB"),
    Variant("PoseTrack", "unitrack_env.envs.posetrack:PoseTrackEnv", {}, "posetrack",
            folder="PoseTrack2018"),
)


def register_all() -> None:
    """Register every variant (idempotent)."""
    for variant in VARIANTS:
        if variant.env_id not in gym.registry:
            gym.register(id=variant.env_id, entry_point=variant.entry_point,
                         kwargs=dict(variant.kwargs), disable_env_checker=False)


def env_ids(task: str | None = None) -> list[str]:
    """Return the registered ids, optionally only those of one task (e.g. ``"mot"``)."""
    return [v.env_id for v in VARIANTS if task is None or v.task == task]


def task_of(env_id: str) -> str:
    """Return the task family of a registered id (``"mot"``, ...)."""
    for variant in VARIANTS:
        if variant.env_id == env_id:
            return variant.task
    raise KeyError(f"'{env_id}' is not a unitrack id; registered: {', '.join(env_ids())}")


def variant(env_id: str) -> Variant:
    """The registration row of ``env_id``."""
    for row in VARIANTS:
        if row.env_id == env_id:
            return row
    raise KeyError(f"'{env_id}' is not a unitrack id; registered: {', '.join(env_ids())}")
