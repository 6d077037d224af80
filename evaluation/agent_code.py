"""The source files an agent's actions depend on, so that edited code never reuses old results.

An agent's results are decided by its own module and by the code it imports: for the
UniTrack heads, the primitives and the appearance model in :mod:`unitrack_env.agents`; for an
agent of yours, also the modules beside its file. :func:`agent_code` reads the imports of
those files (statically, without importing anything) and returns every such file it reaches.

Left out on purpose: installed third-party packages (their versions are not this package's to
track) and the rest of ``unitrack_env`` (environments, readers, geometry), which turn the same
data into the same observations for every agent; ``unitrack_env.__version__`` is in the run
identity for those.
"""

from __future__ import annotations

import ast
import hashlib
import sys
from collections.abc import Iterator
from functools import lru_cache
from pathlib import Path

AGENTS_PACKAGE = "unitrack_env.agents"


def _agents_root() -> Path:
    import unitrack_env.agents

    return Path(unitrack_env.agents.__file__).parent


def _module_file(folder: Path, parts: list[str]) -> Path | None:
    """``folder/a/b.py`` or ``folder/a/b/__init__.py`` for ``parts == ["a", "b"]``."""
    if not parts or not all(p.isidentifier() for p in parts):
        return None
    base = folder.joinpath(*parts)
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def _package_parts(path: Path, root: Path) -> list[str] | None:
    """The package of a file under the agents root, as names after ``unitrack_env.agents``."""
    try:
        relative = path.relative_to(root)
    except ValueError:
        return None
    return list(relative.parts[:-1])


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


def _targets(path: Path, root: Path) -> Iterator[Path]:
    """The files of the agents package, or beside a file of yours, that ``path`` imports."""
    stat = path.stat()
    package = _package_parts(path, root)
    for level, module, name in _imports(path, (stat.st_mtime_ns, stat.st_size)):
        if level:  # relative: within the agents package, or within your folder
            if package is not None:
                if level - 1 > len(package):
                    continue
                base, parts = root, package[:len(package) - level + 1]
            else:
                base, parts = path.parents[level - 1], []
            parts = parts + [p for p in module.split(".") if p]
        elif module == AGENTS_PACKAGE or module.startswith(AGENTS_PACKAGE + "."):
            base, parts = root, module.split(".")[2:]
        elif package is None and module:  # a module of yours beside the agent's file
            base, parts = path.parent, module.split(".")
        else:
            continue
        target = (_module_file(base, [*parts, name]) if name and name != "*" else None) \
            or _module_file(base, parts)
        if target is not None:
            yield target


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
    """The agent's file and every file it imports from the agents package or from beside it.

    Imports are followed through the files they reach; the list is sorted, and empty for a
    reference without a file.
    """
    start = agent_file(reference)
    if start is None:
        return []
    root = _agents_root()
    seen: set[Path] = set()
    todo = [start.resolve()]
    while todo:
        path = todo.pop()
        if path in seen:
            continue
        seen.add(path)
        todo += [target.resolve() for target in _targets(path, root.resolve())
                 if target.resolve() not in seen]
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
    root = _agents_root().resolve()
    home = files[0].parent if (start := agent_file(reference)) is None \
        else start.resolve().parent
    manifest: dict[str, str] = {}
    for path in files:
        if path.is_relative_to(root):
            name = f"unitrack_env/agents/{path.relative_to(root).as_posix()}"
        elif path.is_relative_to(home):
            name = path.relative_to(home).as_posix()
        else:
            name = path.name
        manifest[name] = hashlib.blake2b(path.read_bytes(), digest_size=16).hexdigest()
    return dict(sorted(manifest.items()))


def code_changes(old: dict[str, str], new: dict[str, str]) -> list[str]:
    """The files whose content differs between two manifests (added and removed ones too)."""
    return [name for name in sorted(old.keys() | new.keys()) if old.get(name) != new.get(name)]
