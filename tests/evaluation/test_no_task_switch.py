"""evaluation/ never names a task: everything it does per task, it asks the task's Benchmark.

A task's name is written where its benchmark and its registration row are declared
(``unitrack_env/benchmarks/``, ``unitrack_env/registration.py``) and nowhere in
``evaluation/``: no comparison with it, no table keyed by it, no lookup of it, no default
argument holding it. Docstrings may mention tasks.
"""

from __future__ import annotations

import ast
from pathlib import Path

import unitrack_env
from unitrack_env.benchmarks import benchmark_class
from unitrack_env.registration import variants

EVALUATION = Path(unitrack_env.__file__).resolve().parent.parent / "evaluation"


def task_names() -> set[str]:
    """Every task a registered benchmark states."""
    return {benchmark_class(row).task for row in variants() if row.scoring}


def _docstrings(tree: ast.AST) -> set[int]:
    """ids of the string constants that are docstrings (of modules, classes, functions or
    attributes: a bare string expression)."""
    return {id(node.value) for node in ast.walk(tree)
            if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)}


def task_literals(source: str, where: str, names: set[str]) -> list[str]:
    """``where:line 'task'`` for every string literal naming a task in ``source``'s code."""
    tree = ast.parse(source)
    skip = _docstrings(tree)
    hits = sorted((node.lineno, node.value) for node in ast.walk(tree)
                  if isinstance(node, ast.Constant) and isinstance(node.value, str)
                  and node.value in names and id(node) not in skip)
    return [f"{where}:{line} {value!r}" for line, value in hits]


def test_the_registry_states_the_tasks():
    assert {"mot", "sot", "vos", "mots", "vis", "posetrack", "pose-prop"} <= task_names()


def test_no_task_name_is_written_in_evaluation():
    names = task_names()
    files = sorted(EVALUATION.rglob("*.py"))
    assert len(files) > 20
    found = [hit for path in files for hit in task_literals(
        path.read_text(encoding="utf-8"), str(path.relative_to(EVALUATION.parent)), names)]
    assert found == [], "evaluation/ names tasks (ask the Benchmark instead):\n" + \
        "\n".join(found)


def test_the_scan_finds_switches_tables_and_lookups_but_not_docstrings():
    source = ('"""Tasks: "mot"."""\nif bench.task == "mot":\n    pass\n'
              'SIZES = {"sot": 1}\nx = TABLE.get("vos")\nok = bench.task in ("vis",)\n'
              'def f(task="posetrack"):\n    """The "pose-prop" task."""\n')
    assert task_literals(source, "x.py", task_names()) == [
        "x.py:2 'mot'", "x.py:4 'sot'", "x.py:5 'vos'", "x.py:6 'vis'", "x.py:7 'posetrack'"]
