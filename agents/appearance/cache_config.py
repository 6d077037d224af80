"""Settings of the feature cache: where it lives, how large it may grow, and size texts.

Folder: ``$UNITRACK_FEATURE_CACHE``, ``$UNITRACK_CACHE`` or the user cache folder; cap:
``$UNITRACK_FEATURE_CACHE_MAX`` or :data:`DEFAULT_MAX_SIZE`.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

DEFAULT_CACHE_DTYPE: type[np.floating] = np.float16
"""On-disk dtype of cached features (half the disk of float32, ~5e-4 relative rounding)."""

DEFAULT_MAX_SIZE: int = 10 * 2**30
"""Default cap of the cache folder: 10 GiB, about 4,600 feature maps of 1080p frames at the
default 1088 x 608 input (2.3 MB each), e.g. MOT17's 5,316 unique training frames minus the
sequence used least recently."""

CACHE_DIR_ENV: str = "UNITRACK_FEATURE_CACHE"
"""Environment variable: the cache folder, or ``off`` (also ``0``, ``false``, ``no``,
``none``) to turn the default cache off."""

CACHE_MAX_ENV: str = "UNITRACK_FEATURE_CACHE_MAX"
"""Environment variable: the cap, e.g. ``10GiB``, ``500MB`` or a number of bytes."""

DATA_ENV: str = "UNITRACK_CACHE"
"""The project's cache folder (synthetic data sets); the feature cache defaults to its
``features`` sub-folder."""

APP_NAME: str = "unitrack-env"
"""Application name given to platformdirs."""

_OFF_VALUES = frozenset({"0", "off", "false", "no", "none"})
_SIZE_UNITS = {
    "": 1, "b": 1,
    "k": 2**10, "kib": 2**10, "kb": 10**3,
    "m": 2**20, "mib": 2**20, "mb": 10**6,
    "g": 2**30, "gib": 2**30, "gb": 10**9,
    "t": 2**40, "tib": 2**40, "tb": 10**12,
}
_SIZE = re.compile(r"^\s*([0-9]*\.?[0-9]+)\s*([a-zA-Z]*)\s*$")


def parse_size(text: str | int | float) -> int:
    """Bytes of a size such as ``"10GiB"``, ``"500MB"``, ``"1.5G"`` or ``1048576``.

    ``KiB``.. and bare ``K``.. are powers of 1024, ``kB``.. powers of 1000; ValueError otherwise.
    """
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        value = float(text)
        unit = ""
    else:
        match = _SIZE.match(str(text))
        if match is None or match.group(2).lower() not in _SIZE_UNITS:
            raise ValueError(
                f"not a size: {text!r} (examples: 10GiB, 500MB, 1.5G, 1048576)")
        value, unit = float(match.group(1)), match.group(2).lower()
    if value < 0:
        raise ValueError(f"a size must be >= 0, got {text!r}")
    return int(value * _SIZE_UNITS[unit])


def format_size(num_bytes: float) -> str:
    """``1536`` -> ``"1.5 KiB"`` (binary units)."""
    value = float(num_bytes)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if abs(value) < 1024 or unit == "GiB":
            return f"{value:.0f} {unit}" if unit == "B" else f"{value:.1f} {unit}"
        value /= 1024
    return f"{value:.1f} TiB"  # pragma: no cover - unreachable


def default_cache_dir() -> Path | None:
    """The default cache folder, or None when ``$UNITRACK_FEATURE_CACHE`` turns it off.

    ``$UNITRACK_FEATURE_CACHE``, else ``$UNITRACK_CACHE/features``, else
    ``platformdirs.user_cache_dir("unitrack-env")/features``.
    """
    override = os.environ.get(CACHE_DIR_ENV, "").strip()
    if override:
        return None if override.lower() in _OFF_VALUES else Path(override).expanduser()
    data = os.environ.get(DATA_ENV, "").strip()
    if data:
        return Path(data).expanduser() / "features"
    # lazy: start-up cost (platformdirs; only needed without an override)
    import platformdirs

    return Path(platformdirs.user_cache_dir(APP_NAME)) / "features"


def default_max_size() -> int:
    """The cap: ``$UNITRACK_FEATURE_CACHE_MAX`` or :data:`DEFAULT_MAX_SIZE`."""
    text = os.environ.get(CACHE_MAX_ENV, "").strip()
    if not text:
        return DEFAULT_MAX_SIZE
    try:
        return parse_size(text)
    except ValueError as exc:
        raise ValueError(f"${CACHE_MAX_ENV}: {exc}") from None
