"""Level 1 of UniTrack: the shared appearance model producing stride-8 feature maps.

:class:`AppearanceModel` takes images and returns ``(B, C, ceil(H/8), ceil(W/8))`` features;
the default weights ``"imagenet-lite0"`` (EfficientNet-Lite0, ImageNet, offline) give 112
channels. The package also exports the letterbox, the model identity, weights and checkpoint
loading, and the content-addressed feature cache (list: docs/architecture.md).
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
