"""The on-disk cache of embedded synthetic data sets.

:func:`ensure_synthetic` generates a data set on first use into
``$UNITRACK_CACHE/synthetic/<kind>-<benchmark>-v<GENERATOR_VERSION>/`` (default: the user
cache folder). Creation is atomic (a temporary sibling, a marker written last, a rename); a
final folder without the marker is moved aside and regenerated.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator, Mapping
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

from unitrack_env.datasets.synthetic import davis, motchallenge, otb
from unitrack_env.datasets.synthetic import jhmdb as jhmdb_synthetic
from unitrack_env.datasets.synthetic import mots as mots_synthetic
from unitrack_env.datasets.synthetic import posetrack as posetrack_synthetic
from unitrack_env.datasets.synthetic import tapvid as tapvid_synthetic
from unitrack_env.datasets.synthetic import youtube_vis as vis_synthetic

#: Version of the generated data; bump it whenever any writer's output changes, so that
#: caches of an older generator are not reused.
GENERATOR_VERSION = 2
#: Environment variable that overrides the cache folder.
CACHE_ENV_VAR = "UNITRACK_CACHE"
#: Application name given to platformdirs for the default cache folder.
APP_NAME = "unitrack-env"
#: Sub-folder of the cache holding synthetic data sets.
SYNTHETIC_SUBDIR = "synthetic"
#: File written last into a complete data set.
MARKER_NAME = ".unitrack-synthetic-complete"
#: Temporary folders older than this (seconds) are leftovers of interrupted runs.
STALE_TEMP_SECONDS = 3600.0



@dataclass(frozen=True)
class SyntheticKind:
    """A generator of embedded synthetic data sets.

    ``write(root, benchmark)`` fills ``root``; ``benchmarks`` are those it can generate;
    ``annotated_frames(benchmark, split)`` gives the frames of every annotated sequence it
    writes, known before writing. A benchmark passes its kind to
    :func:`~unitrack_env.benchmarks.base.data_root` (a built-in's by name, a project's own
    as the object), so a new task's generator is not listed here.
    """

    name: str
    write: Callable[[Path, str], None]
    benchmarks: tuple[str, ...]
    annotated_frames: Callable[[str, str | None], dict[str, int]]


#: The built-in generators, by name.
KINDS: Mapping[str, SyntheticKind] = MappingProxyType({kind.name: kind for kind in (
    SyntheticKind("motchallenge", motchallenge.write_motchallenge, motchallenge.BENCHMARKS,
                  motchallenge.annotated_frames),
    SyntheticKind("otb", otb.write_otb, otb.BENCHMARKS, otb.annotated_frames),
    SyntheticKind("davis", davis.write_davis, davis.BENCHMARKS, davis.annotated_frames),
    SyntheticKind("mots", mots_synthetic.write_mots, mots_synthetic.BENCHMARKS,
                  mots_synthetic.annotated_frames),
    SyntheticKind("youtube_vis", vis_synthetic.write_youtube_vis, vis_synthetic.BENCHMARKS,
                  vis_synthetic.annotated_frames),
    SyntheticKind("jhmdb", jhmdb_synthetic.write_jhmdb, ("JHMDB",),
                  jhmdb_synthetic.annotated_frames),
    SyntheticKind("posetrack", posetrack_synthetic.write_posetrack,
                  posetrack_synthetic.BENCHMARKS, posetrack_synthetic.annotated_frames),
    SyntheticKind("tapvid", tapvid_synthetic.write_tapvid, tapvid_synthetic.BENCHMARKS,
                  tapvid_synthetic.annotated_frames),
)})


def synthetic_kind(kind: str | SyntheticKind) -> SyntheticKind:
    """``kind`` itself, or the built-in generator of that name (else a ValueError)."""
    if isinstance(kind, SyntheticKind):
        return kind
    if kind not in KINDS:
        raise ValueError(f"unknown synthetic data kind {kind!r}; valid: {', '.join(KINDS)}")
    return KINDS[kind]


_SPECS_ONLY: ContextVar[bool] = ContextVar("unitrack_synthetic_specs_only", default=False)


class SpecsOnly(LookupError):
    """:func:`ensure_synthetic` was called within :func:`specs_only`.

    ``benchmark`` and ``kind`` are its arguments, ``path`` where the data set is (or will
    be), ``generated`` whether it is complete there.
    """

    def __init__(self, benchmark: str, kind: SyntheticKind, path: Path) -> None:
        self.benchmark, self.kind, self.path = benchmark, kind, path
        self.generated = is_complete(path)
        super().__init__(f"the synthetic {kind.name} data set {benchmark} ({path}) was asked for "
                         "within specs_only()")


@contextlib.contextmanager
def specs_only() -> Iterator[None]:
    """Within: :func:`ensure_synthetic` raises :class:`SpecsOnly`, generating nothing.

    For quick looks that must not wait for generation or reading, such as how many frames a
    run will play: :func:`annotated_frames` tells that from the writers' specs.
    """
    token = _SPECS_ONLY.set(True)
    try:
        yield
    finally:
        _SPECS_ONLY.reset(token)


def annotated_frames(benchmark: str, kind: str | SyntheticKind = "motchallenge",
                     split: str | None = None) -> dict[str, int]:
    """Frames of each annotated sequence of ``split`` (None: any) of a synthetic data set.

    The same as reading the generated data set, without generating it.
    """
    synthetic_path(benchmark, kind)  # validates both
    return synthetic_kind(kind).annotated_frames(benchmark, split)


def cache_root() -> Path:
    """Return the cache folder: ``$UNITRACK_CACHE`` or the user cache dir."""
    override = os.environ.get(CACHE_ENV_VAR)
    if override:
        return Path(override).expanduser()
    # lazy: start-up cost (platformdirs; only needed without the override)
    import platformdirs

    return Path(platformdirs.user_cache_dir(APP_NAME))


def synthetic_path(benchmark: str, kind: str | SyntheticKind = "motchallenge") -> Path:
    """Return where the synthetic ``benchmark`` data set of ``kind`` is (or will be) cached."""
    generator = synthetic_kind(kind)
    if benchmark not in generator.benchmarks:
        raise ValueError(
            f"no synthetic {generator.name} data for benchmark {benchmark!r}; valid: "
            f"{', '.join(generator.benchmarks)}"
        )
    return (cache_root() / SYNTHETIC_SUBDIR
            / f"{generator.name}-{benchmark}-v{GENERATOR_VERSION}")


def is_complete(path: Path) -> bool:
    """Whether ``path`` holds a completely written synthetic data set (its marker exists)."""
    return (path / MARKER_NAME).is_file()


def ensure_synthetic(benchmark: str, kind: str | SyntheticKind = "motchallenge") -> Path:
    """Return the root (holding ``train/`` and ``test/``) of a synthetic data set, generated once.

    Unknown ``kind`` or ``benchmark`` raise ValueError; an unwritable cache raises OSError
    (set ``UNITRACK_CACHE`` elsewhere).
    """
    final = synthetic_path(benchmark, kind)
    generator = synthetic_kind(kind)
    if _SPECS_ONLY.get():
        raise SpecsOnly(benchmark, generator, final)
    if is_complete(final):
        return final
    parent = final.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise OSError(
            f"cannot create the synthetic data cache {parent} ({error}); set "
            f"{CACHE_ENV_VAR} to a writable folder"
        ) from error
    _remove_stale_temps(parent, final.name)
    temp = Path(tempfile.mkdtemp(prefix=f".{final.name}.tmp-", dir=parent))
    try:
        generator.write(temp, benchmark)
        marker = {"kind": generator.name, "benchmark": benchmark,
                  "generator_version": GENERATOR_VERSION}
        (temp / MARKER_NAME).write_text(json.dumps(marker, sort_keys=True) + "\n")
        if final.exists() and not is_complete(final):
            _discard(final, parent)
        try:
            os.rename(temp, final)
        except OSError:
            if not is_complete(final):  # not a lost race: a real failure
                raise
    finally:
        if temp.exists():
            shutil.rmtree(temp, ignore_errors=True)
    return final


def _discard(path: Path, parent: Path) -> None:
    """Move an incomplete data set aside (atomically) and delete it."""
    trash = Path(tempfile.mkdtemp(prefix=f".{path.name}.trash-", dir=parent))
    try:
        os.rename(path, trash / path.name)
    except FileNotFoundError:  # someone else already moved it
        pass
    shutil.rmtree(trash, ignore_errors=True)


def _remove_stale_temps(parent: Path, name: str) -> None:
    """Delete temporary folders of interrupted runs older than :data:`STALE_TEMP_SECONDS`."""
    now = time.time()
    for prefix in (f".{name}.tmp-", f".{name}.trash-"):
        for path in parent.glob(f"{prefix}*"):
            try:
                if now - path.stat().st_mtime > STALE_TEMP_SECONDS:
                    shutil.rmtree(path, ignore_errors=True)
            except FileNotFoundError:
                pass
