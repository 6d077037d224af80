"""The library's module graph has no cycle, counting the imports placed inside functions.

Every ``import``/``from ... import`` of a project module anywhere in a library file is an
edge (at module level, in a function, in a class), except those under
``if TYPE_CHECKING:``, which never run. ``from package import name`` points at the
submodule ``package.name`` when there is one, else at ``package``; a module importing a
submodule does not count as importing its parent packages (``__init__`` files are nodes of
their own). The whole of ``unitrack_env`` is scanned, its ``agents`` and ``evaluation``
included.
"""

from __future__ import annotations

import ast
import functools
import os
import re
import sys
from pathlib import Path

import unitrack_env

PACKAGE = Path(unitrack_env.__file__).resolve().parent
ROOT = "unitrack_env"


def library_modules() -> dict[str, Path]:
    """``{dotted name: file}`` of every module of the library (symlinked parts followed)."""
    modules = {}
    files = [Path(folder) / name for folder, _, names in os.walk(PACKAGE, followlinks=True)
             for name in names if name.endswith(".py")]
    for path in sorted(files):
        parts = path.relative_to(PACKAGE).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        modules[".".join((ROOT, *parts))] = path
    return modules


def _type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import node of ``tree`` outside ``if TYPE_CHECKING:`` blocks."""
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _type_checking(node.test):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import | ast.ImportFrom):
            found.append(node)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return found


def imported(module: str, path: Path, tree: ast.AST, known: set[str]) -> set[str]:
    """The library modules that ``module`` (file ``path``) imports."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out: set[str] = set()
    for node in _imports(tree):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        else:
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[:len(anchor) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            targets = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base
                       for alias in node.names]
        out |= {t for t in targets if t in known and t != module}
    return out


@functools.cache  # parsed once for the tests below
def module_graph() -> dict[str, set[str]]:
    """``{module: modules it imports}`` of the whole library."""
    modules = library_modules()
    known = set(modules)
    return {name: imported(name, path, ast.parse(path.read_text(encoding="utf-8")), known)
            for name, path in modules.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def connect(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for succ in sorted(graph.get(node, ())):
            if succ not in index:
                connect(succ)
                low[node] = min(low[node], low[succ])
            elif succ in on_stack:
                low[node] = min(low[node], index[succ])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            connect(node)
    return sorted(found)


def test_the_scan_sees_function_level_and_relative_imports():
    source = ("from typing import TYPE_CHECKING\nfrom . import b\n"
              "if TYPE_CHECKING:\n    from .c import C\n"
              "def f():\n    from .d import g\n    import pkg.e\n")
    known = {"pkg.a", "pkg.b", "pkg.c", "pkg.d", "pkg.e", "pkg"}
    assert imported("pkg.a", Path("pkg/a.py"), ast.parse(source), known) == {
        "pkg.b", "pkg.d", "pkg.e"}
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_the_graph_covers_the_library():
    graph = module_graph()
    assert {"unitrack_env.evaluation.run.runner", "unitrack_env.agents.base",
            "unitrack_env.benchmarks.base"} <= set(graph)
    assert "unitrack_env.evaluation.analysis.events" in graph["unitrack_env.evaluation.run.runner"]


def test_the_library_has_no_import_cycle():
    found = cycles(module_graph())
    assert found == [], "import cycles (function-level imports counted):\n" + "\n".join(
        " <-> ".join(component) for component in found)


#: A function-level import says why it is not at module level, in one of these words, on its
#: line or on the comment line just above its run of imports (issue 37, item 4).
LAZY_REASON = re.compile(r"# lazy: (optional dependency|start-up cost|import cycle) \(.+\)")
def unreasoned_imports(source: str) -> list[int]:
    """Lines of the function-level imports of ``source`` (standard library excepted) that
    carry no :data:`LAZY_REASON`."""
    lines = source.splitlines()
    missing: list[int] = []

    def check_run(run: list[ast.Import | ast.ImportFrom]) -> None:
        above = lines[run[0].lineno - 2] if run[0].lineno >= 2 else ""
        for node in run:
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else [
                node.module or ""]
            if not getattr(node, "level", 0) and all(n.split(".")[0] in sys.stdlib_module_names
                                      for n in names):
                continue
            own = "\n".join(lines[node.lineno - 1:node.end_lineno])
            if not (LAZY_REASON.search(own) or LAZY_REASON.fullmatch(above.strip())):
                missing.append(node.lineno)

    def visit(node: ast.AST, in_function: bool) -> None:
        in_function = in_function or isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
        for field in ("body", "orelse", "finalbody", "handlers"):
            block = getattr(node, field, None)
            if not isinstance(block, list):
                continue
            run: list[ast.Import | ast.ImportFrom] = []
            for stmt in block:
                if in_function and isinstance(stmt, ast.Import | ast.ImportFrom):
                    if run and stmt.lineno - 1 != run[-1].end_lineno:  # a comment between
                        check_run(run)
                        run = []
                    run.append(stmt)
                    continue
                if run:
                    check_run(run)
                    run = []
            if run:
                check_run(run)
        for child in ast.iter_child_nodes(node):
            visit(child, in_function)

    visit(ast.parse(source), False)
    return sorted(missing)


def test_the_reason_check_sees_bare_and_commented_imports():
    source = ("import torch\n"
              "def f():\n    import json\n    from .a import b\n"
              "    # lazy: start-up cost (torch)\n    import torch\n    import cv2\n"
              "    x = 1\n    import pandas  # lazy: optional dependency (pandas)\n"
              "    if x:\n        import ray  # lazily, for speed\n")
    assert unreasoned_imports(source) == [4, 11]


def test_every_function_level_import_says_why():
    missing = [f"{path}:{line}" for path in library_modules().values()
               for line in unreasoned_imports(path.read_text(encoding="utf-8"))]
    assert missing == [], ("function-level imports without a '# lazy: <reason> (...)' comment "
                           "(move them to module level, or say why not):\n" + "\n".join(missing))
