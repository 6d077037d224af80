"""The source files an agent's actions depend on, so that edited code never reuses old results.

An agent's results are decided by its own module and by the code it imports: for the UniTrack
heads, the primitives and the appearance model in :mod:`unitrack_env.agents`; for an agent of
yours, also the modules beside its file or in its package. :func:`agent_code` reads the
imports of those files (statically, without importing anything) and returns every such file it
reaches, plus the other modules of ``unitrack_env`` they import directly (``geometry``'s IoU,
a mask codec, an environment's track cap), without following those further.

Left out on purpose: installed third-party packages (their versions are not this package's to
track) and the rest of ``unitrack_env`` (environment internals, readers, metrics), which turn
the same data into the same observations for every agent; ``unitrack_env.__version__`` is in
the run identity for those.
"""

from __future__ import annotations

import ast
import hashlib
import sys
from collections.abc import Iterator
from functools import lru_cache
from pathlib import Path

import unitrack_env.agents


def _roots() -> tuple[Path, Path]:
    """The folders of ``unitrack_env`` and of ``unitrack_env.agents`` (links resolved)."""
    return (Path(unitrack_env.__file__).resolve().parent,
            Path(unitrack_env.agents.__file__).resolve().parent)


def _module_file(folder: Path, parts: list[str]) -> Path | None:
    """``folder/a/b.py`` or ``folder/a/b/__init__.py`` for ``parts == ["a", "b"]``."""
    if not parts or not all(p.isidentifier() for p in parts):
        return None
    base = folder.joinpath(*parts)
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate.resolve()
    return None


def _module_name(path: Path, agents: Path) -> list[str] | None:
    """``["unitrack_env", "agents", ...]`` for a file of the agents package, else None."""
    try:
        relative = path.relative_to(agents)
    except ValueError:
        return None
    parts = ["unitrack_env", "agents", *relative.with_suffix("").parts]
    return parts[:-1] if parts[-1] == "__init__" else parts


@lru_cache(maxsize=512)
def _imports(path: Path, _stamp: tuple[int, int]) -> tuple[tuple[int, str, str | None], ...]:
    """Every import of a file: ``(level, module, imported name or None)``."""
    try:
        tree = ast.parse(path.read_bytes(), filename=str(path))
    except (SyntaxError, ValueError, OSError):
        return ()  # the import of the agent reports it; its bytes still count
    found: list[tuple[int, str, str | None]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(0, alias.name, None) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            found += [(node.level, node.module or "", alias.name) for alias in node.names]
    return tuple(found)


def _targets(path: Path) -> Iterator[tuple[Path, bool]]:
    """The files ``path`` imports that count, each with whether its imports count too."""
    package_root, agents = _roots()
    stat = path.stat()
    own = _module_name(path, agents)
    package = None if own is None else (own if path.name == "__init__.py" else own[:-1])
    for level, module, name in _imports(path, (stat.st_mtime_ns, stat.st_size)):
        words = [w for w in module.split(".") if w]
        if level and package is not None:  # relative, inside the package
            if level - 1 >= len(package):
                continue
            words = package[:len(package) - level + 1] + words
        elif level:  # relative, in your folder
            found = _resolve(path.parents[level - 1], words, name)
            if found is not None:
                yield found, True
            continue
        if words[:2] == ["unitrack_env", "agents"]:
            found = _resolve(agents, words[2:], name)
        elif words[:1] == ["unitrack_env"] and len(words) > 1:
            found = _resolve(package_root, words[1:], name)
            if found is not None:
                yield found, False  # one hop into the rest of unitrack_env
            continue
        elif package is None and words:  # yours: beside the file, or in its package
            found = _resolve(path.parent, words, name) \
                or _resolve(_import_root(path.parent), words, name)
        else:
            continue
        if found is not None:
            yield found, True


def _import_root(folder: Path) -> Path:
    """The folder above the outermost package holding ``folder`` (itself outside packages)."""
    while (folder / "__init__.py").is_file() and folder.parent != folder:
        folder = folder.parent
    return folder


def _resolve(folder: Path, parts: list[str], name: str | None) -> Path | None:
    """The file of ``from <parts> import <name>``: the submodule ``name``, else ``parts``."""
    return (_module_file(folder, [*parts, name]) if name and name != "*" else None) \
        or _module_file(folder, parts)


def agent_file(reference: str) -> Path | None:
    """The file that defines the agent of a ``module:Class`` or ``path.py:Class`` reference."""
    target, sep, _ = reference.rpartition(":")
    if not sep:
        return None
    if target.endswith(".py") or "/" in target or "\\" in target:
        path = Path(target)
    else:
        path = Path(getattr(sys.modules.get(target), "__file__", None) or "")
    return path if path.name and path.is_file() else None


def agent_code(reference: str) -> list[Path]:
    """The agent's file and the files it imports from the agents package or from beside it.

    Imports are followed through the files they reach; other ``unitrack_env`` modules they
    import are listed, not followed. The list is sorted, and empty for a reference without a
    file.
    """
    start = agent_file(reference)
    if start is None:
        return []
    seen: set[Path] = set()
    todo = [(start.resolve(), True)]
    while todo:
        path, follow = todo.pop()
        if path in seen:
            continue
        seen.add(path)
        if follow:
            todo += [(target, more) for target, more in _targets(path) if target not in seen]
    return sorted(seen)


def code_manifest(reference: str) -> dict[str, str]:
    """``{name: digest of the content}`` of :func:`agent_code`, for a run's records.

    Files of the agents package are named from ``unitrack_env/agents/``, files of yours
    relative to the agent's folder (or by base name, outside it): where they live does not
    count, what they hold does.
    """
    files = agent_code(reference)
    if not files:
        return {}
    package_root, agents = _roots()
    start = agent_file(reference)
    home = start.resolve().parent if start is not None else files[0].parent
    manifest: dict[str, str] = {}
    for path in files:
        if path.is_relative_to(agents):
            name = f"unitrack_env/agents/{path.relative_to(agents).as_posix()}"
        elif path.is_relative_to(package_root):
            name = f"unitrack_env/{path.relative_to(package_root).as_posix()}"
        elif path.is_relative_to(home):
            name = path.relative_to(home).as_posix()
        else:
            name = path.name
        manifest[name] = hashlib.blake2b(path.read_bytes(), digest_size=16).hexdigest()
    return dict(sorted(manifest.items()))


def code_changes(old: dict[str, str], new: dict[str, str]) -> list[str]:
    """The files whose content differs between two manifests (added and removed ones too)."""
    return [name for name in sorted(old.keys() | new.keys()) if old.get(name) != new.get(name)]
