"""The bad-input corpus: every case is refused (or warned about, or accepted where the official
tools accept it) with a message that holds its expected content; docs/bad-inputs.md lists them.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def _script():
    name = "make_bad_input_docs"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, REPO / "scripts" / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


DOCS = _script()
CORPUS = DOCS.load_cases()


def test_corpus_is_large_and_covers_every_reader():
    ids = [case.id for case in CORPUS.CASES]
    assert len(ids) == len(set(ids)), "case ids must be unique"
    assert len(ids) >= 80
    areas = {case.area for case in CORPUS.CASES}
    assert {"MOT", "MOTS", "VIS", "PoseTrack", "OTB", "DAVIS", "JHMDB", "action",
            "checkpoint"} <= areas


@pytest.mark.parametrize("case", CORPUS.CASES, ids=lambda case: case.id)
def test_case_is_clear(case, tmp_path: Path):
    outcome = CORPUS.outcome(case, tmp_path)
    assert outcome.verdict == "clear", (
        f"{case.id} ({case.what}): {outcome.verdict}, {outcome.kind}: {outcome.message}\n"
        f"expected a {case.kind} containing {case.expect}")


def test_docs_page_lists_every_case_with_its_message():
    page = DOCS.PAGE
    assert page.is_file(), "docs/bad-inputs.md missing: run python scripts/make_bad_input_docs.py"
    rows = DOCS.parse_rows(page.read_text())
    stale = "docs/bad-inputs.md is stale: run python scripts/make_bad_input_docs.py"
    assert sorted(rows) == sorted(case.id for case in CORPUS.CASES), stale
    for case in CORPUS.CASES:
        cells = rows[case.id]
        assert cells[:4] == DOCS.row_key(case), f"{stale} ({case.id})"
        # Messages may differ in detail between machines (byte counts, library wording);
        # the page must show a clear outcome whose message holds the expected content.
        assert cells[5] == "clear", f"{stale} ({case.id} is {cells[5]})"
        message = DOCS.uncell(cells[6])
        assert all(fragment in message for fragment in case.expect), f"{stale} ({case.id})"
