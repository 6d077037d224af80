"""Level 1 of UniTrack: the shared appearance model producing stride-8 feature maps.

Public API:

* :class:`AppearanceModel` -- images in, ``(B, C, ceil(H/8), ceil(W/8))`` features out;
  default weights ``"imagenet-lite0"`` (EfficientNet-Lite0, ImageNet, offline; stage5 run
  at stride 8, 112 channels).
* :func:`letterbox` / :class:`Letterbox` -- JDE-style 1088 x 608 letterbox with box mapping.
* :class:`ModelIdentity` -- (architecture, layer, weights digest, normalisation) for cache keys.
* Checkpoints: :class:`LoadReport`, :class:`KeyRemap`, :data:`DEFAULT_REMAPS`,
  :class:`CheckpointError`, :func:`load_checkpoint`.
* Weights (:mod:`~unitrack_env.agents.appearance.weights`): :data:`DEFAULT_WEIGHT_LOADERS`,
  :class:`WeightsSource`, :func:`load_weights`, :func:`resolve_weights`,
  :class:`LoadedWeights`; :class:`AppearanceSpec`, the appearance fields of every head's
  config.
* Cache (content-addressed, bounded, on by default): :class:`FeatureCache`, :class:`CacheKey`,
  :class:`CachedAppearanceModel`, :func:`content_key`, :func:`track_cache_run`.
* Architectures: :class:`ResNet`, :class:`EfficientNetLite0`.
"""

from unitrack_env.errors import CheckpointError

from .architectures import (
    ARCHITECTURES,
    DEFAULT_LAYERS,
    FEATURE_STRIDE,
)
from .cache_config import default_cache_dir
from .cache_files import FeatureCacheWarning
from .cache_keys import CacheKey, content_key
from .cache_runs import CacheStats, track_cache_run
from .cached_model import CachedAppearanceModel
from .checkpoints import (
    CIFAR_MEAN,
    CIFAR_STD,
    DEFAULT_REMAPS,
    IMAGENET_MEAN,
    IMAGENET_STD,
    KeyRemap,
    LoadReport,
    load_checkpoint,
)
from .efficientnet_lite import EfficientNetLite0
from .feature_cache import FeatureCache, resolve_cache
from .identity import ModelIdentity, weights_digest
from .letterboxing import (
    MOT_INPUT_SIZE,
    Letterbox,
    letterbox,
    letterbox_layout,
)
from .model import AppearanceModel, torch_threads
from .resnet import ResNet, infer_resnet_arch
from .spec import AppearanceSpec
from .weights import (
    DEFAULT_WEIGHT_LOADERS,
    LoadedWeights,
    WeightsSource,
    load_weights,
    resolve_weights,
)

__all__ = [
    "ARCHITECTURES",
    "CIFAR_MEAN",
    "CIFAR_STD",
    "DEFAULT_LAYERS",
    "DEFAULT_REMAPS",
    "DEFAULT_WEIGHT_LOADERS",
    "FEATURE_STRIDE",
    "IMAGENET_MEAN",
    "IMAGENET_STD",
    "MOT_INPUT_SIZE",
    "AppearanceModel",
    "AppearanceSpec",
    "CacheKey",
    "CacheStats",
    "CachedAppearanceModel",
    "CheckpointError",
    "EfficientNetLite0",
    "FeatureCache",
    "FeatureCacheWarning",
    "KeyRemap",
    "Letterbox",
    "LoadReport",
    "LoadedWeights",
    "ModelIdentity",
    "ResNet",
    "WeightsSource",
    "content_key",
    "default_cache_dir",
    "infer_resnet_arch",
    "letterbox",
    "letterbox_layout",
    "torch_threads",
    "load_checkpoint",
    "load_weights",
    "resolve_cache",
    "resolve_weights",
    "track_cache_run",
    "weights_digest",
]
