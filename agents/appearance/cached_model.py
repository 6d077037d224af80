"""The appearance model whose per-frame features are served through the feature cache."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from unitrack_env.provenance import note_runtime

from .cache_config import CACHE_DIR_ENV
from .cache_files import _as_float32
from .cache_keys import CacheKey, content_key
from .feature_cache import FeatureCache, resolve_cache
from .model import AppearanceModel


class CachedAppearanceModel:
    """An :class:`AppearanceModel` whose per-frame features go through a :class:`FeatureCache`.

    Frames are looked up by content; the backbone runs once, batched, on the misses.
    ``cache`` resolving to no cache raises ValueError (use the model itself).

    Example:
        >>> cached = CachedAppearanceModel(AppearanceModel(), "/tmp/feats")  # doctest: +SKIP
        >>> maps = cached.features(frames)                                   # doctest: +SKIP
    """

    def __init__(
        self,
        model: AppearanceModel,
        cache: FeatureCache | str | os.PathLike[str] | bool = True,
        *,
        max_size: int | str | None = None,
    ) -> None:
        resolved = resolve_cache(cache, max_size=max_size)
        if resolved is None:
            raise ValueError(f"feature_cache={cache!r} turns the cache off "
                             f"(${CACHE_DIR_ENV}={os.environ.get(CACHE_DIR_ENV, '')!r}); "
                             "use the appearance model itself")
        self.model = model
        self.cache = resolved
        self.identity = model.identity
        self.channels = model.channels
        self.stride = model.stride
        self._model_key = model.identity.key()

    def describe(self) -> dict[str, Any]:
        """The wrapped model's description plus the cache location."""
        return {**self.model.describe(), "cache": str(self.cache.root)}

    def _info(self) -> dict[str, Any]:
        with contextlib.suppress(Exception):  # descriptive only
            return {"model": self.model.describe()}
        return {}

    def key(self, input_size: tuple[int, int], content: str) -> CacheKey:
        """The :class:`CacheKey` of a frame at ``input_size`` = (height, width)."""
        return CacheKey(self._model_key, (int(input_size[0]), int(input_size[1])), content)

    def lookup(self, input_size: tuple[int, int], content: str) -> torch.Tensor | None:
        """The cached ``(1, C, h, w)`` map of one frame, or None (a hit counts; a miss does not)."""
        array, _ = self.cache._read(self.key(input_size, content),
                                    self.model.feature_shape(*input_size))
        if array is None:
            return None
        self.cache.stats.hits += 1
        note_runtime(self.model.runtime_label(*input_size))
        return _as_float32(array)[None]

    def features(
        self,
        images: np.ndarray | Sequence[np.ndarray],
        *,
        keys: Sequence[str] | None = None,
    ) -> torch.Tensor:
        """Feature maps ``(B, C, h, w)`` of same-size uint8 inputs, from the cache if possible.

        ``keys`` are the entries' :func:`content_key` (default: of ``images``), so a caller can
        key by the original frame and skip the letterbox on a hit. Returns float32 CPU features.
        """
        batch = np.asarray(images) if not isinstance(images, np.ndarray) else images
        if batch.ndim == 3:
            batch = batch[None]
        if keys is None:
            keys = [content_key(img) for img in batch]
        if len(keys) != batch.shape[0]:
            raise ValueError(f"{batch.shape[0]} images but {len(keys)} keys")
        input_size = (int(batch.shape[1]), int(batch.shape[2]))
        expected = self.model.feature_shape(*input_size)
        found: dict[int, np.ndarray] = {}
        todo: list[tuple[int, bool]] = []
        stats = self.cache.stats
        for i, content in enumerate(keys):
            array, corrupt = self.cache._read(self.key(input_size, content), expected)
            if array is not None:
                stats.hits += 1
                found[i] = array
            else:
                todo.append((i, corrupt))
                if corrupt:
                    stats.corrupt += 1
                else:
                    stats.misses += 1
        if found:  # served from the cache: computed by the runtime its key names
            note_runtime(self.model.runtime_label(*input_size))
        if todo:
            computed = self.model.features(batch[[i for i, _ in todo]]).to("cpu")
            info = self._info()
            for row, (i, corrupt) in enumerate(todo):
                found[i] = self.cache.put(self.key(input_size, keys[i]), computed[row],
                                          replace=corrupt, model_info=info)
        return _as_float32(np.stack([found[i] for i in range(len(keys))]))

    def flush_stats(self) -> None:
        """Record the cache's counters on disk (see :meth:`FeatureCache.flush_stats`)."""
        self.cache.flush_stats()


def with_cache(model: AppearanceModel, option: FeatureCache | str | os.PathLike[str] | bool | None,
               *, dtype: type[np.floating] = np.float32,
               max_size: int | str | None = None) -> AppearanceModel | CachedAppearanceModel:
    """``model`` served through the cache ``option`` names, or ``model`` itself.

    The propagation heads' use: float32 entries by default, so results equal the uncached ones.
    """
    if not hasattr(model, "identity"):
        return model
    cache = resolve_cache(option, max_size=max_size, dtype=dtype)
    return model if cache is None else CachedAppearanceModel(model, cache)
