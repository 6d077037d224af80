"""Agents by reference: ``module:Class``, ``path/to/file.py:Class`` and installed plug-ins.

Besides a registered name, an agent is named by ``"package.module:ClassName"`` (imported as
``python -m`` would: the current folder first), ``"path/to/file.py:ClassName"`` (loaded as a
module, keyed by path and content so an edited file loads anew), or a name an installed
distribution publishes in the ``unitrack_env.agents`` entry-point group
(``[project.entry-points."unitrack_env.agents"] my-tracker = "my_package.tracker:MyTracker"``).
:func:`agent_reference` turns a class back into such a string; the runner stores it in
``run.json`` so that workers and resumed runs rebuild the same class without the user's
registry state.
"""

from __future__ import annotations

import difflib
import hashlib
import importlib
import importlib.machinery
import importlib.metadata
import importlib.util
import sys
from pathlib import Path
from typing import Any

#: Entry-point group in which installed distributions publish named agents.
ENTRY_POINT_GROUP = "unitrack_env.agents"


def entry_point_agents() -> dict[str, importlib.metadata.EntryPoint]:
    """Named agents published by installed distributions (not imported yet)."""
    return {ep.name: ep for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)}


def is_reference(spec: str) -> bool:
    """Whether ``spec`` is a ``module:Class`` or ``file.py:Class`` reference (not a name)."""
    target, sep, attribute = spec.rpartition(":")
    return bool(sep and target and attribute and "/" not in attribute and "\\" not in attribute)


def _search_first(folder: Path) -> None:
    """Put ``folder`` first on ``sys.path`` (once).

    As ``python`` does for a script's folder and ``python -m`` for the current one: a user's
    module imports the files beside it.
    """
    entry = str(folder)
    if entry not in sys.path:
        sys.path.insert(0, entry)


def _load_file(path: Path) -> Any:
    if not path.is_file():
        raise FileNotFoundError(f"agent file {path} does not exist")
    resolved = path.resolve()
    # Keyed by path and content: an edited file is loaded anew in the same process (a notebook).
    digest = hashlib.sha1(str(resolved).encode() + resolved.read_bytes()).hexdigest()[:10]
    name = f"unitrack_user_agents.{resolved.stem}_{digest}"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, resolved)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load {resolved} as a Python module")
    _search_first(resolved.parent)
    try:
        return _execute(name, spec)
    except ImportError as exc:
        raise ImportError(f"agent file {path}: {exc}") from exc


def _execute(name: str, spec: importlib.machinery.ModuleSpec) -> Any:
    """Create, register and run the module ``name`` from ``spec`` (unregistered on failure)."""
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module


def _import_module(name: str) -> Any:
    """Import ``name`` as ``python -m`` would: the current folder first, then ``sys.path``.

    So ``--agent agents.mine:MyTracker`` imports the user's own ``agents/`` even where an
    installed distribution provides a top-level ``agents`` (openai-agents does).
    """
    top = name.partition(".")[0]
    local = (importlib.machinery.PathFinder.find_spec(top, [str(Path.cwd())])
             if top not in sys.modules else None)
    if local is not None and local.loader is not None:
        _search_first(Path.cwd())
        _execute(top, local)
        return importlib.import_module(name)
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        origin = getattr(sys.modules.get(top), "__file__", None)
        if origin is None:
            raise
        shadowed = importlib.machinery.PathFinder.find_spec(top, [str(Path.cwd())])
        if shadowed is None or shadowed.origin == origin:
            raise
        raise ModuleNotFoundError(
            f"{exc}: '{top}' is already imported from {origin}, which hides ./{top}; name "
            f"the file instead ({name.replace('.', '/')}.py:ClassName)", name=exc.name,
        ) from None


def did_you_mean(name: str, choices: list[str]) -> str:
    """``"did you mean X? "`` for the choices closest to ``name`` (case aside), else ``""``."""
    lowered: dict[str, str] = {}
    for choice in choices:
        lowered.setdefault(choice.lower(), choice)
    close = difflib.get_close_matches(name.lower(), list(lowered), n=3, cutoff=0.6)
    return f"did you mean {' or '.join(lowered[c] for c in close)}? " if close else ""


def _is_file(target: str) -> bool:
    return target.endswith(".py") or "/" in target or "\\" in target


def load_reference(spec: str) -> type:
    """Import the class named by ``module:Class`` or ``path/to/file.py:Class``.

    An ImportError says what could not be imported and how a reference is written.
    """
    target, _, attribute = spec.rpartition(":")
    if _is_file(target):
        module = _load_file(Path(target))
    else:
        try:
            module = _import_module(target)
        except ModuleNotFoundError as exc:
            raise ImportError(
                f"agent '{spec}': cannot import module '{target}' ({exc}); a reference is "
                "'package.module:ClassName' (importable from the current folder or an installed "
                "distribution) or 'path/to/file.py:ClassName'"
            ) from None
    obj: Any = module
    for part in attribute.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            classes = [n for n, v in vars(obj).items() if isinstance(v, type)
                       and getattr(v, "__module__", None) == getattr(obj, "__name__", None)]
            hint = did_you_mean(part, classes).rstrip()
            raise ImportError(f"agent '{spec}': {target} has no attribute '{attribute}'"
                              + (f"; {hint}" if hint else "")) from None
    if not isinstance(obj, type):
        raise ImportError(f"agent '{spec}' is not a class but {type(obj).__name__}")
    return obj


def agent_reference(cls: type) -> str:
    """An importable ``module:Qualname`` for ``cls`` (a file path for file-loaded classes)."""
    module = sys.modules.get(cls.__module__)
    if cls.__module__.startswith("unitrack_user_agents.") and module is not None:
        return f"{module.__file__}:{cls.__qualname__}"
    return f"{cls.__module__}:{cls.__qualname__}"


def portable_reference(cls: type) -> str | None:
    """:func:`agent_reference`, or None when another process could not import it.

    A class defined in ``__main__`` of an interactive session (a notebook, ``python -c``) or
    in ``exec``'d code exists nowhere a worker process could import it from; a script's
    ``__main__`` is re-imported by ``spawn`` workers, so its classes are portable.
    """
    if cls.__module__ == "__main__":
        main = sys.modules.get("__main__")
        if getattr(main, "__file__", None) is None:
            return None
        found: Any = main  # a class inside a function, or exec'd: not at its qualname
        for part in cls.__qualname__.split("."):
            found = getattr(found, part, None)
        return agent_reference(cls) if found is cls else None
    reference = agent_reference(cls)
    try:
        found = load_reference(reference)
    except (ImportError, FileNotFoundError):
        return None
    return reference if found is cls else None
