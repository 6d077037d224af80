"""Embedded synthetic data sets: small, deterministic, in each benchmark's exact layout.

Without ``root=``, an environment reads :func:`ensure_synthetic`'s folder with the same reader
as real data. :func:`render_scene` draws textured people that walk, cross and occlude each
other; writers put the scenes on disk in a benchmark's layout.
"""

from unitrack_env.datasets.synthetic.cache import (
    CACHE_ENV_VAR,
    GENERATOR_VERSION,
    cache_root,
    ensure_synthetic,
    is_complete,
    synthetic_path,
)
from unitrack_env.datasets.synthetic.motchallenge import (
    DEFAULT_SPEC,
    DetectionNoise,
    Detections,
    MotChallengeSpec,
    SequenceSpec,
    simulate_detections,
    write_motchallenge,
)
from unitrack_env.datasets.synthetic.scene import SyntheticVideo, render_scene
from unitrack_env.datasets.synthetic.scene_model import (
    ObjectAnnotation,
    ObjectRole,
    Pattern,
    SceneConfig,
    SceneObject,
    Silhouette,
    SyntheticFrame,
    Texture,
    Trajectory,
)

__all__ = [
    "CACHE_ENV_VAR",
    "DEFAULT_SPEC",
    "GENERATOR_VERSION",
    "DetectionNoise",
    "Detections",
    "MotChallengeSpec",
    "ObjectAnnotation",
    "ObjectRole",
    "Pattern",
    "SceneConfig",
    "SceneObject",
    "SequenceSpec",
    "Silhouette",
    "SyntheticFrame",
    "SyntheticVideo",
    "Texture",
    "Trajectory",
    "cache_root",
    "ensure_synthetic",
    "is_complete",
    "render_scene",
    "simulate_detections",
    "synthetic_path",
    "write_motchallenge",
]
