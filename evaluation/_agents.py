"""Import of the ``agents`` package with a clear error when another one shadows it.

Other distributions (for example ``openai-agents``) also install a top-level package named
``agents``. When one of them wins the import, every agent lookup would fail obscurely; this
module names the culprit and the fix instead.
"""

from __future__ import annotations

import importlib
from types import ModuleType


def agents_module() -> ModuleType:
    """Return unitrack's ``agents`` package, or raise ImportError explaining a clash."""
    module = importlib.import_module("agents")
    if not getattr(module, "UNITRACK_AGENTS", False):
        location = getattr(module, "__file__", None) or list(getattr(module, "__path__", []))
        raise ImportError(
            f"the 'agents' package imported from {location} is not unitrack-env's: another "
            "distribution (e.g. openai-agents) installs a top-level 'agents' package too. "
            "Use a separate virtual environment for unitrack-env, or uninstall the other "
            "distribution (pip show -f <name> lists its files)."
        )
    return module
