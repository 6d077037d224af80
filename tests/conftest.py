"""Shared test fixtures: hermetic synthetic-data cache and the real fixtures in ../shared."""

from __future__ import annotations

import importlib
import os
import sys
import types
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: Real benchmark fixtures beside the repository (absent in a user's clone).
SHARED_DATA = (REPO / ".." / "shared" / "data").resolve()


@pytest.fixture(scope="session", autouse=True)
def _hermetic_environment(tmp_path_factory: pytest.TempPathFactory):
    """Generate synthetic data into a per-session cache; ignore a user's UNITRACK_DATA.

    The feature cache (on by default) and the compiled-runtime cache go to per-session
    folders too, never the user's; a user's UNITRACK_RUNTIME does not change the results
    (tests run torch).
    """
    keys = ("UNITRACK_CACHE", "UNITRACK_DATA", "UNITRACK_FEATURE_CACHE",
            "UNITRACK_FEATURE_CACHE_MAX", "UNITRACK_FEATURE_CACHE_RUN", "UNITRACK_RUNTIME",
            "UNITRACK_RUNTIME_CACHE")
    saved = {k: os.environ.get(k) for k in keys}
    os.environ["UNITRACK_CACHE"] = str(tmp_path_factory.mktemp("unitrack-cache"))
    os.environ["UNITRACK_FEATURE_CACHE"] = str(tmp_path_factory.mktemp("feature-cache"))
    os.environ.pop("UNITRACK_FEATURE_CACHE_MAX", None)
    os.environ.pop("UNITRACK_FEATURE_CACHE_RUN", None)
    os.environ.pop("UNITRACK_DATA", None)
    # torch, the reference, unless a test says (the default, "auto", would compile OpenVINO
    # in every test that builds a model)
    os.environ["UNITRACK_RUNTIME"] = "torch"
    os.environ["UNITRACK_RUNTIME_CACHE"] = str(tmp_path_factory.mktemp("runtime-cache"))
    yield
    for key, value in saved.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The ``../shared/data`` folder, or skip when it is not beside the repository."""
    if not SHARED_DATA.is_dir():
        pytest.skip("../shared/data is not available (only in the project's own checkout)")
    return SHARED_DATA


@pytest.fixture(scope="session")
def mot17_root(shared_data: Path) -> Path:
    """Real MOT17 clips (4 short FRCNN sequences)."""
    return shared_data / "MOT17"


@pytest.fixture(scope="session")
def mot15_root(shared_data: Path) -> Path:
    """Real MOT15 PETS09-S2L1 (400 frames)."""
    return shared_data / "MOT15"


@pytest.fixture(scope="module")
def got10k_experiments():
    """The ``got10k`` package's ``experiments`` module (the parity reference of the SOT
    protocols). Modules it imports at load time only for downloads and polygons (six, wget,
    shapely), which none of the functions the tests call use, are replaced by empty ones when
    they are not installed (a ``--no-deps`` install) and removed again afterwards."""
    pytest.importorskip("got10k")
    added = []
    for name in ("six", "wget", "shapely", "shapely.geometry"):
        try:
            importlib.import_module(name)
        except ImportError:
            module = types.ModuleType(name)
            module.box = module.Polygon = None
            module.string_types = str
            sys.modules[name] = module
            added.append(name)
    try:
        yield importlib.import_module("got10k.experiments")
    finally:
        for name in added:
            sys.modules.pop(name, None)
