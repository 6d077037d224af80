"""unitrack-env: visual tracking benchmarks as Gymnasium environments.

>>> import gymnasium as gym
>>> import unitrack_env
>>> "UniTrack/MOT17-v0" in gym.registry
True
"""

from unitrack_env import vector as _vector  # noqa: F401 - shared memory for vector envs
from unitrack_env.registration import (
    VARIANTS,
    Variant,
    env_ids,
    register_all,
    register_variant,
    task_of,
    variant,
    variants,
)

__version__ = "0.1.0"
__all__ = ["VARIANTS", "Variant", "env_ids", "register_all", "register_variant", "task_of",
           "variant", "variants", "__version__"]

register_all()
