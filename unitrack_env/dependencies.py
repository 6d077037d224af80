"""Runtime dependencies that pip cannot install for us, checked before any frame is played.

TrackEval cannot be a declared requirement (its metadata asks for the GUI ``opencv-python``,
which would overwrite the headless ``cv2``), so it is installed with ``--no-deps`` and an
environment that scores with it checks for it when made, not at an episode's last step.
"""

from __future__ import annotations

import importlib.util

#: The command that installs each optional runtime dependency the right way.
FIXES: dict[str, str] = {
    "trackeval": "pip install --no-deps trackeval==1.3.0",
}


class MissingDependencyError(ImportError):
    """A runtime dependency is not installed; the message holds the command that fixes it."""


def require(module: str, purpose: str) -> None:
    """Raise :class:`MissingDependencyError` unless ``module`` can be imported."""
    if importlib.util.find_spec(module) is None:
        fix = FIXES.get(module, f"pip install {module}")
        raise MissingDependencyError(
            f"{purpose} needs the '{module}' package, which is not installed; fix: {fix}"
        )
