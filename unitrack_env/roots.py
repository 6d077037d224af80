"""Where a data set is read from: ``root=``, ``$UNITRACK_DATA/<folder>``, or the synthetic default.

Environments and benchmarks both resolve their data folder here (no silent fallback: a
``root`` or ``$UNITRACK_DATA`` that names a missing folder is an error).
"""

from __future__ import annotations

import os
from pathlib import Path

from unitrack_env.errors import DataFormatError

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
