"""The ``>>>`` examples of every library module run, and print what their docstrings say.

Each module of the installed namespace (``unitrack_env``, with ``unitrack_env.agents`` and
``unitrack_env.evaluation``) is imported and its docstring examples are run with
:mod:`doctest`; an example that needs data or a network is marked ``# doctest: +SKIP``.
"""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import numpy as np
import pytest

import unitrack_env

#: Modules not imported here: their import has side effects meant for another process.
NOT_IMPORTED = {"unitrack_env.evaluation.regression.plugin"}

FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


def library_modules() -> list[str]:
    """Every module of the library, by its installed name."""
    names = [unitrack_env.__name__]
    for info in pkgutil.walk_packages(unitrack_env.__path__, prefix="unitrack_env."):
        if info.name not in NOT_IMPORTED:
            names.append(info.name)
    return sorted(names)


def examples(module_name: str) -> list[doctest.DocTest]:
    """The doctests of ``module_name`` that have examples."""
    module = importlib.import_module(module_name)
    finder = doctest.DocTestFinder(exclude_empty=True)
    return [test for test in finder.find(module, module_name) if test.examples]


MODULES = library_modules()


def test_the_library_has_examples_to_run() -> None:
    """The sweep finds the packages' modules and their examples (it cannot pass empty)."""
    assert "unitrack_env.agents.primitives.kalman" in MODULES
    assert "unitrack_env.evaluation.cli" in MODULES
    assert sum(len(examples(name)) for name in MODULES) >= 30


@pytest.mark.parametrize("module_name", MODULES)
def test_docstring_examples_run(module_name: str) -> None:
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    failures = []
    with np.printoptions(legacy=False):
        for test in examples(module_name):
            result = runner.run(test, out=failures.append, clear_globs=True)
            if result.failed:
                failures.append(f"-- {test.name}: {result.failed} failed\n")
    assert not failures, "".join(failures)
