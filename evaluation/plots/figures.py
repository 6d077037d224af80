"""Matplotlib for the library's figures: imported on demand, saved the same way by all.

Every figure the library writes (success and precision plots, attribute and scorecard radars,
correlation scatters) is a PNG and an SVG with the same bytes for the same data (no date in
the SVG, a fixed salt for its element ids), and its figure is closed even when saving fails.
matplotlib is an optional dependency (the ``plots`` extra): without it there is a warning
and no figure.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any


def pyplot(what: str) -> Any | None:
    """``matplotlib.pyplot`` on the Agg backend, or None with a warning naming ``what``."""
    try:
        import matplotlib  # lazy: optional dependency (matplotlib)

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt  # lazy: optional dependency (matplotlib)
    except ImportError:
        warnings.warn(f"no {what}: matplotlib is missing (pip install 'unitrack-env[plots]')",
                      stacklevel=3)
        return None
    return plt


def save_figure(figure: Any, stem: Path, salt: str, *, dpi: int = 120,
                tight: bool = True) -> list[Path]:
    """Write ``<stem>.png`` and ``<stem>.svg`` (reproducible bytes); close ``figure``."""
    import matplotlib  # lazy: optional dependency (matplotlib)
    import matplotlib.pyplot as plt  # lazy: optional dependency (matplotlib)

    written = []
    try:
        with matplotlib.rc_context({"svg.hashsalt": salt}):
            for suffix in (".png", ".svg"):
                path = stem.parent / f"{stem.name}{suffix}"
                figure.savefig(path, dpi=dpi, bbox_inches="tight" if tight else None,
                               metadata={"Date": None} if suffix == ".svg" else None)
                written.append(path)
    finally:
        plt.close(figure)
    return written
