"""Every documented figure is a command, and the fixture-based ones are replayed cell by cell.

THE CONVENTION (follow it when you add or change a table of numbers in README.md or
docs/*.md; the full grammar is in scripts/update_doc_figures.py's docstring). Right above the
table, an HTML comment names the commands the numbers come from and maps the cells to them;
each command is also printed, verbatim, in the visible text of the same section::

    <!-- figures
    $ unitrack evaluate --env UniTrack/MOT16-v0 --agent iou --out runs/mot16-iou
    cell Synthetic MOT16 | `iou` <- $1 COMBINED | HOTA / IDF1 / MOTA
    replay $1 ci: the IoU baseline on two short clips, seconds
    -->

- ``cell * | * <- $1 * | *``: the table has the command's own rows and metric columns.
- ``skip <column>: why`` for cells that are not replayed (a speed figure: name the command
  and the CPU in the text); ``tolerance <column glob> <points>: why`` where a figure moves
  between CPUs, with the measurement that justifies it.
- ``replay $N ci|slow|benchmark|manual|test <file>::<test>: why``: ``ci`` replays run in CI
  (``-k replay_in_ci`` in .ci/run; keep them to seconds), ``slow`` ones under ``-m slow``,
  ``benchmark`` ones only with ``UNITRACK_REPLAY_BENCHMARKS=1`` (they need the network or
  half an hour), ``manual`` ones never (a machine measurement), ``test`` ones by the named
  test, which calls :func:`compare` on its own output (a scorecard is not played twice).

Never edit a number by hand: ``python scripts/update_doc_figures.py [--only TEXT]
[--benchmarks]`` replays the commands and rewrites the cells (``--check`` only lists them).
A cell matches when the replayed value, printed the way the document prints it (percent
with one decimal, counts as integers), equals the documented text, or is within the
column's stated tolerance.
"""

from __future__ import annotations

import importlib.util
import os
import re
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def load_figures():
    """scripts/update_doc_figures.py as a module (scripts/ is not a package)."""
    if "update_doc_figures" in sys.modules:
        return sys.modules["update_doc_figures"]
    spec = importlib.util.spec_from_file_location("update_doc_figures",
                                                  REPO / "scripts" / "update_doc_figures.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


figures_module = load_figures()
FOUND, MISSING = figures_module.all_figures()


#: Sources whose documented cells wait for a change on another branch, with the reason. Each
#: is a strict xfail: once the change has landed the replay passes, the xfail fails, and the
#: entry must go (keyed by the command).
PENDING: dict[str, str] = {}


def _sources(kind: str) -> list:
    """(figures, source number) of every source replayed as ``kind``, one test each."""
    out = []
    for figures in FOUND:
        for n, command in enumerate(figures.sources, start=1):
            if figures.replay(n) != kind:
                continue
            marks = [pytest.mark.xfail(strict=True, reason=PENDING[command])] \
                if command in PENDING else []
            out.append(pytest.param(figures, n, id=f"{figures.table.label()}-${n}",
                                    marks=marks))
    return out


def _section(doc: str, line: int) -> str:
    """The visible text of the section (between headings) that holds ``line`` of ``doc``."""
    lines = (REPO / doc).read_text().splitlines()
    start = max((i for i in range(line) if lines[i].startswith("#")), default=0)
    end = next((i for i in range(line, len(lines)) if lines[i].startswith("#")), len(lines))
    text = re.sub(r"<!--.*?-->", " ", "\n".join(lines[start:end]), flags=re.S)
    return " ".join(text.replace("\\\n", " ").replace("`", " ").split())


def test_every_table_of_numbers_names_its_commands():
    assert not MISSING, ("tables of numbers without a <!-- figures --> comment above them "
                         "(see tests/test_doc_figures.py): "
                         + ", ".join(t.label() for t in MISSING))
    assert {f.table.doc for f in FOUND} >= {"README.md", "docs/quickstart.md",
                                            "docs/evaluate-your-representation.md"}


def test_every_numeric_cell_has_a_source_and_every_source_a_replay():
    problems = []
    for figures in FOUND:
        problems += [f"not sourced: {cell}" for cell in figures_module.unmapped(figures)]
        where = figures.table.label()
        for cell in figures.cells:
            if not 1 <= cell.source <= len(figures.sources):
                problems.append(f"{where}: cell {cell.row!r} names ${cell.source}")
        for n in range(1, len(figures.sources) + 1):
            kind = figures.replay(n)
            if kind not in figures_module.REPLAYS:
                problems.append(f"{where}: ${n} has replay kind {kind!r}")
            if kind == "test":
                path, _, name = figures.replayed_by(n).partition("::")
                if not (REPO / path).is_file() or f"def {name}(" not in (REPO / path).read_text():
                    problems.append(f"{where}: ${n} names a test that does not exist")
            if kind in ("ci", "slow", "test") and not any(c.source == n for c in figures.cells):
                problems.append(f"{where}: ${n} is replayed but sources no cell")
        for name, (_, why) in figures.ci_env.items():
            if not why:
                problems.append(f"{where}: ci-env {name} without a reason")
    assert not problems, "\n".join(problems)


def test_every_command_is_printed_beside_its_table():
    hidden = [f"{f.table.label()}: {command}" for f in FOUND for command in f.sources
              if " ".join(command.split()) not in _section(f.table.doc, f.line)]
    assert not hidden, ("commands of a figures comment that the section does not print "
                        "(a reader must see them):\n" + "\n".join(hidden))


@pytest.mark.parametrize("command", sorted({c for f in FOUND for c in f.sources}),
                         ids=lambda command: re.sub(r"[^\w.=-]+", "_", command)[:90])
def test_every_command_parses(command):
    figures_module.dry_parse(command)


def _replay(figures, n: int, tmp_path: Path) -> None:
    outputs = {n: figures_module.run_source(figures.sources[n - 1], tmp_path)}
    wrong = figures_module.compare(figures, outputs)
    assert not wrong, (f"documented cells differ from the output of `{figures.sources[n - 1]}`"
                       " (if the change is intended: python scripts/update_doc_figures.py):\n"
                       + "\n".join(map(str, wrong)))


# Named so that CI's `-m slow -k "scorecard or pets or replay_in_ci"` picks them. A figures
# comment's `ci-env` lines apply here only (e.g. a faster runtime whose features equal
# torch's to float rounding); the slow replays and the update script run the plain commands.
@pytest.mark.slow
@pytest.mark.parametrize(("figures", "n"), _sources("ci"))
def test_replay_in_ci(figures, n, tmp_path, monkeypatch, request):
    if any(part.startswith("../shared/") for part in figures.sources[n - 1].split()):
        request.getfixturevalue("shared_data")  # skips without the fixtures
    for name, (value, _) in figures.ci_env.items():
        monkeypatch.setenv(name, value)
    _replay(figures, n, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize(("figures", "n"), _sources("slow"))
def test_replay_slow_doc_figures(figures, n, tmp_path, shared_data):
    _replay(figures, n, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize(("figures", "n"), _sources("benchmark"))
def test_replay_benchmark_doc_figures(figures, n, tmp_path, shared_data):
    if os.environ.get("UNITRACK_REPLAY_BENCHMARKS") != "1":
        pytest.skip("benchmark figures (network, half an hour): UNITRACK_REPLAY_BENCHMARKS=1")
    _replay(figures, n, tmp_path)


def test_a_wrong_cell_is_reported_with_its_documented_and_replayed_value():
    figures = next(f for f in FOUND if f.table.doc == "docs/quickstart.md")
    rows = {row[0]: dict(zip(figures.table.header[1:], row[1:], strict=True))
            for row in figures.table.rows}
    assert figures_module.compare(figures, {1: rows}) == []
    assert figures_module.compare(figures, {}) == []  # nothing replayed, nothing compared
    rows["COMBINED"]["HOTA"] = "12.3"
    [wrong] = figures_module.compare(figures, {1: rows})
    assert str(wrong) == (f"{figures.table.label()} row 'COMBINED', column 'HOTA': "
                          f"documented '59.7', replayed '12.3' (tolerance 0)")
    rows["COMBINED"]["FPS"] = "1.0"  # skipped: a speed figure
    assert len(figures_module.compare(figures, {1: rows})) == 1


def test_tolerances_and_bold_marks():
    card = next(f for f in FOUND if f.table.doc == "docs/evaluate-your-representation.md"
                and f.sources[0].startswith("unitrack scorecard"))
    assert card.tolerance("SOT* AUC (XCorr) ↑") == 1.0
    assert card.tolerance("VOS* J-Mean ↑") == 0.2
    same = figures_module._same
    assert same("**60.5**", "59.6", 1.0) and not same("**60.5**", "59.4", 1.0)
    assert same("54.1 / 80.0 / 72.9", "54.1 / 80.0 / 72.9", 0.0)
    assert not same("54.1 / 80.0 / 72.9", "51.3 / 73.8 / 61.1", 0.2)
    assert not same("-", "0.0", 1.0)


def test_a_row_the_document_lacks_is_reported():
    figures = next(f for f in FOUND if f.table.doc == "docs/quickstart.md")
    rows = {row[0]: dict(zip(figures.table.header[1:], row[1:], strict=True))
            for row in figures.table.rows}
    rows["SYN-03"] = rows["SYN-01"]
    [wrong] = figures_module.compare(figures, {1: rows})
    assert (wrong.row, wrong.documented) == ("SYN-03", "<not in the document>")


def test_a_benchmark_table_is_read_by_its_leading_text_cells():
    """The rows benchmarks/mot_agent.py prints map onto README's MOT cells."""
    printed = """[accuracy] combined metrics per data set (percent; IDSW count)
| data | agent | HOTA | IDF1 | MOTA | IDSW | DetA | AssA |
|---|---|---|---|---|---|---|---|
| PETS09-S2L1 | roboflow sort | 36.3 | 46.1 | 63.1 | 50 | 40.0 | 33.0 |
| PETS09-S2L1 | roboflow bytetrack | 37.6 | 50.1 | 72.7 | 40 | 41.0 | 34.0 |

| data | sequence | setting | true_dets |
|---|---|---|---|
| PETS09-S2L1 | PETS09-S2L1 | defaults | 4000 |
"""
    rows = figures_module._markdown_rows(printed)
    assert rows["PETS09-S2L1 / roboflow sort"]["IDF1"] == "46.1"
    assert rows["PETS09-S2L1 / PETS09-S2L1 / defaults"] == {"true_dets": "4000"}
    readme = next(f for f in FOUND if f.table.doc == "README.md" and f.table.rows)
    n = next(i for i, c in enumerate(readme.sources, start=1) if "mot_agent.py" in c)
    wrong = figures_module.compare(readme, {n: rows})
    assert {(w.row.split()[0], w.column) for w in wrong} == {
        ("hard", c) for c in ("`unitrack`", "paper setting", "`iou`", "SORT", "ByteTrack")}


def test_the_scorecard_page_reads_back_as_a_scorecard(tmp_path):
    """What tests/evaluation/test_scorecard.py compares: scorecard.md rows vs the page."""
    card = next(f for f in FOUND if f.table.doc == "docs/evaluate-your-representation.md"
                and f.sources[0].startswith("unitrack scorecard"))
    lines = [f"| {' | '.join(card.table.header)} |", "|" + "---|" * len(card.table.header)]
    lines += [f"| {' | '.join(row)} |" for row in card.table.rows]
    (tmp_path / "scorecard.md").write_text("\n".join(lines) + "\n\n- SOT*: ...\n")
    rows = figures_module.scorecard_rows(tmp_path)
    assert figures_module.compare(card, {1: rows}) == []
    sot, vos = "SOT* AUC (XCorr) ↑", "VOS* J-Mean ↑"
    rows["random"][sot] = f"{float(rows['random'][sot]) + 0.9:.1f}"
    rows["random"][vos] = f"{float(rows['random'][vos]) + 0.3:.1f}"
    [wrong] = figures_module.compare(card, {1: rows})
    assert (wrong.row, wrong.column, wrong.tolerance) == ("random", vos, 0.2)
