"""Every documented figure is a command: find it, replay it, compare or rewrite the cells.

Usage:
  python scripts/update_doc_figures.py                 # replay every fixture-based table, rewrite
  python scripts/update_doc_figures.py --check         # replay and list the cells that differ
  python scripts/update_doc_figures.py --only MOT15    # only the commands that contain "MOT15"
  python scripts/update_doc_figures.py --benchmarks    # also the tables a benchmark script makes

The convention (tests/test_doc_figures.py enforces it): every table of numbers in README.md and
docs/*.md (a markdown table, or a fenced block of terminal output drawn with box characters)
has, right above it (blank lines allowed), an HTML comment that says where its numbers come
from; each command it names is also printed, verbatim, in the visible text of the same
section, so a reader sees it::

    <!-- figures
    $ unitrack evaluate --env UniTrack/MOT16-v0 --agent iou --out runs/mot16-iou
    cell Synthetic MOT16 | `iou` <- $1 COMBINED | HOTA / IDF1 / MOTA
    cell * | * <- $1 * | *
    skip FPS: frames per second of the machine that ran it (a speed figure)
    tolerance SOT* 1.0: why this column moves between CPUs
    replay $1 ci: why CI may afford it (ci, slow, benchmark, manual, or test <file>::<name>)
    ci-env UNITRACK_RUNTIME=auto: why the ci replay may set this (it must not move a figure)
    -->

``$ command`` lines are the sources (``$1``, ``$2``, ... in order), run from the repository
root. ``cell <doc row> | <doc column> <- $N <output row> | <metric> / <metric>`` maps a cell
to values of a source's output; ``*`` on the left means every row (column) of the table, on
the right the doc's own row (column) name. Outputs: ``unitrack evaluate`` gives its sequences
and ``COMBINED`` with TrackEval's metric names, printed as the CLI prints them (percent with
one decimal, counts as integers); ``unitrack scorecard`` gives the rows of the
``scorecard.md`` it writes; a ``python`` script gives the rows of the markdown tables it
prints, named by their leading text cells joined with `` / ``. A cell matches when the
replayed text equals the documented one (bold marks aside), or when each number differs by
at most the column's tolerance (default 0: the same rounding as the document). Every numeric
cell must be mapped or skipped. The replay redirects ``--out`` into a temporary folder and
adds ``--format json --quiet`` to ``unitrack evaluate``: neither changes a figure. A scorecard
whose ``--out`` is a committed card (a folder under ``docs/results/``, whose cells took hours
to play) is replayed from a copy of that folder: its stored cells are scored again and only
the cells it lacks are played.
"""

from __future__ import annotations

import argparse
import contextlib
import fnmatch
import io
import json
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: Pages generated whole by a script whose test keeps them up to date: their figures are
#: that script's output (docs/envs/*.md come from the env docstrings, tests/test_docs.py).
GENERATED = {"docs/bad-inputs.md": "python scripts/make_bad_input_docs.py, checked by "
                                   "tests/corpus/test_bad_inputs.py"}
#: Documents whose tables are checked.
DOCS = ("README.md", *sorted(f"docs/{p.name}" for p in (REPO / "docs").glob("*.md")
                             if f"docs/{p.name}" not in GENERATED))
#: Replay kinds: who replays a source's cells.
REPLAYS = ("ci", "slow", "benchmark", "manual", "test")
NUMBER = re.compile(r"-?\d+(?:\.\d+)?")
#: A decimal figure outside code spans, not part of a name such as PCK@0.1 or MOT17.
DECIMAL = re.compile(r"(?<![\w@.\-/])\d+\.\d+(?![\w.])")
BOX_CHARS = "│┃"


@dataclass
class Table:
    """A table of a document: its header, rows (lists of cell text) and where it stands."""

    doc: str
    line: int  # 1-based line of its first row
    header: list[str]
    rows: list[list[str]]
    box: bool = False

    def label(self) -> str:
        """``doc:line``, how messages name the table."""
        return f"{self.doc}:{self.line}"


@dataclass
class Cell:
    """``cell <row> | <column> <- $N <output row> | <metrics>``."""

    row: str
    column: str
    source: int
    out_row: str
    metrics: list[str]


@dataclass
class Figures:
    """The ``<!-- figures ... -->`` comment above a table."""

    table: Table
    line: int
    sources: list[str] = field(default_factory=list)
    cells: list[Cell] = field(default_factory=list)
    skips: list[tuple[str, str]] = field(default_factory=list)
    tolerances: list[tuple[str, float, str]] = field(default_factory=list)
    replays: dict[int, tuple[str, str]] = field(default_factory=dict)
    ci_env: dict[str, tuple[str, str]] = field(default_factory=dict)

    def replay(self, source: int) -> str:
        """``ci``, ``slow`` (the default), ``benchmark``, ``manual`` or ``test``."""
        return self.replays.get(source, ("slow", ""))[0].split(" ", 1)[0]

    def replayed_by(self, source: int) -> str:
        """The test named by ``replay $N test <file>::<name>`` (empty otherwise)."""
        return self.replays.get(source, ("", ""))[0].partition(" ")[2].strip()

    def tolerance(self, column: str) -> float:
        """The first matching ``tolerance`` line's value for ``column`` (default 0)."""
        return next((tol for glob, tol, _ in self.tolerances
                     if fnmatch.fnmatchcase(column, glob)), 0.0)

    def skipped(self, column: str) -> bool:
        """Whether a ``skip`` line excuses ``column`` from the comparison."""
        return any(fnmatch.fnmatchcase(column, glob) for glob, _ in self.skips)


# ------------------------------------------------------------------------------ parsing
def _split_row(line: str, box: bool) -> list[str]:
    if box:
        parts = re.split(f"[{BOX_CHARS}]", line)
    else:
        parts = re.split(r"(?<!\\)\|", line.strip())
    return [p.strip() for p in parts[1:-1]]


def tables(doc: str) -> list[tuple[int, Table]]:
    """Every table of ``doc`` (relative to the repository) with the index of the line before it.

    Markdown tables and box-drawn terminal tables inside fenced blocks; for a box table the
    line before is the one before the fence.
    """
    lines = (REPO / doc).read_text().splitlines()
    found, i, fence = [], 0, None
    while i < len(lines):
        line = lines[i]
        if line.startswith("```"):
            fence = None if fence is not None else i
        elif fence is None and line.startswith("|") and i + 1 < len(lines) and \
                re.match(r"^\|[-:| ]+\|$", lines[i + 1]):
            j = i + 2
            while j < len(lines) and lines[j].startswith("|"):
                j += 1
            rows = [_split_row(row, False) for row in lines[i + 2:j]]
            found.append((i - 1, Table(doc, i + 1, _split_row(line, False), rows)))
            i = j
            continue
        elif fence is not None and line.startswith("┃"):
            j = i + 1
            while j < len(lines) and not lines[j].startswith("```"):
                j += 1
            body = [_split_row(row, True) for row in lines[i + 1:j] if row.startswith("│")]
            for row in body:  # the CLI's "COMBINED (2 of 2 sequences)" is the COMBINED row
                row[0] = re.sub(r" \(\d+ of \d+ sequences\)$", "", row[0])
            found.append((fence - 1, Table(doc, i + 1, _split_row(line, True), body, box=True)))
            i, fence = j + 1, None
            continue
        i += 1
    return found


def is_numeric(cell: str) -> bool:
    """A cell that states a figure: a decimal number outside code spans, or numbers alone."""
    text = re.sub(r"`[^`]*`", "", cell).replace("*", "").strip()
    return bool(DECIMAL.search(text)) or bool(re.fullmatch(r"[\d.\s/%x-]*\d[\d.\s/%x-]*", text))


def _comment_above(lines: list[str], before: int) -> tuple[int, list[str]] | None:
    """The ``<!-- figures`` comment ending at or above line ``before`` (blank lines skipped)."""
    i = before
    while i >= 0 and not lines[i].strip():
        i -= 1
    if i < 0 or not lines[i].rstrip().endswith("-->"):
        return None
    end = i
    while i >= 0 and "<!--" not in lines[i]:
        i -= 1
    if i < 0 or not lines[i].strip().startswith("<!-- figures"):
        return None
    body = "\n".join(lines[i:end + 1])
    body = body.strip()[len("<!-- figures"):-len("-->")]
    return i + 1, [line.strip() for line in body.splitlines() if line.strip()]


def _parse_cell(text: str) -> Cell:
    left, right = text[len("cell "):].split(" <- ", 1)
    row, column = (part.strip() for part in left.split(" | ", 1))
    match = re.fullmatch(r"\$(\d+) (.+?) \| (.+)", right.strip())
    if not match:
        raise ValueError(f"a cell line reads 'cell ROW | COLUMN <- $N OUTPUT ROW | METRIC "
                         f"[/ METRIC]': {text!r}")
    metrics = [m.strip() for m in match.group(3).split(" / ")]
    return Cell(row, column, int(match.group(1)), match.group(2).strip(), metrics)


def _parse_line(figures: Figures, text: str) -> None:
    if text.startswith("$ "):
        figures.sources.append(text[2:].strip())
    elif text.startswith("cell "):
        figures.cells.append(_parse_cell(text))
    elif text.startswith("skip "):
        glob, _, why = text[len("skip "):].partition(": ")
        figures.skips.append((glob.strip(), why.strip()))
    elif text.startswith("tolerance "):
        head, _, why = text[len("tolerance "):].partition(": ")
        glob, value = head.rsplit(" ", 1)
        figures.tolerances.append((glob.strip(), float(value), why.strip()))
    elif text.startswith("replay "):
        head, _, why = text[len("replay "):].partition(": ")
        source, kind = head.split(" ", 1)
        figures.replays[int(source.lstrip("$"))] = (kind.strip(), why.strip())
    elif text.startswith("ci-env "):
        head, _, why = text[len("ci-env "):].partition(": ")
        name, _, value = head.strip().partition("=")
        figures.ci_env[name] = (value, why.strip())
    else:
        raise ValueError(f"unknown line in a figures comment: {text!r}")


def _parsed(doc: str, table: Table, comment: tuple[int, list[str]]) -> Figures:
    figures = Figures(table, comment[0])
    for text in comment[1]:
        try:
            _parse_line(figures, text)
        except ValueError as exc:
            raise ValueError(f"{doc}:{comment[0]}: {exc}") from None
    return figures


def figures_of(doc: str) -> tuple[list[Figures], list[Table]]:
    """The figures comments of ``doc``, and the numeric tables that have none.

    A comment above a paragraph instead of a table (figures quoted in prose, e.g. speed
    figures) gets an empty table: its commands are checked, there are no cells to compare.
    """
    lines = (REPO / doc).read_text().splitlines()
    found, missing, used = [], [], set()
    for before, table in tables(doc):
        comment = _comment_above(lines, before)
        if comment is None:
            if any(is_numeric(c) for row in table.rows for c in row[1:]):
                missing.append(table)
            continue
        used.add(comment[0])
        found.append(_parsed(doc, table, comment))
    for i, line in enumerate(lines):
        if line.strip().startswith("<!-- figures") and i + 1 not in used:
            end = next(k for k in range(i, len(lines)) if lines[k].rstrip().endswith("-->"))
            comment = _comment_above(lines, end)
            found.append(_parsed(doc, Table(doc, i + 1, [], []), comment))
    return found, missing


def all_figures() -> tuple[list[Figures], list[Table]]:
    """:func:`figures_of` over every checked document."""
    found, missing = [], []
    for doc in DOCS:
        f, m = figures_of(doc)
        found += f
        missing += m
    return found, missing


def visible_text(doc: str) -> str:
    """The document without HTML comments, whitespace and line continuations collapsed."""
    text = re.sub(r"<!--.*?-->", " ", (REPO / doc).read_text(), flags=re.S)
    return " ".join(text.replace("\\\n", " ").replace("`", " ").split())


# ------------------------------------------------------------------------------ replaying
#: Where committed scorecard folders live (replayed from their stored cells).
RESULTS = "docs/results/"


def committed_card(command: str) -> Path | None:
    """The committed folder a scorecard command writes into (``--out docs/results/...``)."""
    words = shlex.split(command)
    if words[:2] != ["unitrack", "scorecard"] or "--out" not in words[:-1]:
        return None
    out = words[words.index("--out") + 1]
    return REPO / out if out.startswith(RESULTS) else None


def _redirect_out(argv: list[str], folder: Path) -> list[str]:
    argv = list(argv)
    if "--out" in argv:
        argv[argv.index("--out") + 1] = str(folder)
    return argv


def _markdown_rows(text: str) -> dict[str, dict[str, str]]:
    """Rows of every markdown table in ``text``, keyed by their leading text cells."""
    rows: dict[str, dict[str, str]] = {}
    lines = text.splitlines()
    for i, line in enumerate(lines[:-1]):
        if not (line.startswith("|") and re.match(r"^\|[-:| ]+\|$", lines[i + 1])):
            continue
        header = _split_row(line, False)
        body = []
        for row in lines[i + 2:]:
            if not row.startswith("|"):
                break
            body.append(_split_row(row, False))
        keys = 1
        while keys < len(header) - 1 and any(not NUMBER.fullmatch(r[keys].replace("*", ""))
                                             and r[keys] != "-" for r in body):
            keys += 1
        for row in body:
            name = " / ".join(row[:keys])
            rows.setdefault(name, dict(zip(header[keys:], row[keys:], strict=False)))
    return rows


@contextlib.contextmanager
def _in_repo():
    """Run from the repository root (the documents' paths are relative to it)."""
    import os

    before = os.getcwd()
    os.chdir(REPO)
    try:
        yield
    finally:
        os.chdir(before)


def _run_unitrack(argv: list[str]) -> str:
    from unitrack_env.evaluation.cli import main

    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        status = main(argv)
    if status != 0:
        raise RuntimeError(f"unitrack {shlex.join(argv)} exited with status {status}")
    return stdout.getvalue()


def run_source(command: str, work: Path) -> dict[str, dict[str, str]]:
    """Run one ``$`` command from the repository root; its output rows (cell text)."""
    words = shlex.split(command)
    folder = work / "out"
    if words[:2] == ["unitrack", "evaluate"]:
        argv = _redirect_out(words[1:], folder) + ["--quiet"]
        with _in_repo():
            _run_unitrack(argv)
        return evaluate_rows(folder)
    if words[:2] == ["unitrack", "scorecard"]:
        card = committed_card(command)
        if card is not None and card.is_dir():
            shutil.copytree(card, folder)
        with _in_repo():
            _run_unitrack(_redirect_out(words[1:], folder) + ["--quiet"])
        return scorecard_rows(folder)
    if words[0] == "python":
        done = subprocess.run([sys.executable, *_redirect_out(words[1:], folder)], cwd=REPO,
                              capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"{command} exited with status {done.returncode}:\n"
                               f"{done.stderr[-2000:]}")
        return _markdown_rows(done.stdout)
    raise ValueError(f"cannot replay {command!r}: a source is `unitrack evaluate`, "
                     "`unitrack scorecard` or `python <script>`")


def evaluate_rows(folder: Path) -> dict[str, dict[str, str]]:
    """The rows (each sequence and ``COMBINED``) of the ``metrics.json`` a run wrote."""
    from unitrack_env.evaluation.analysis.tables import format_cell

    payload = json.loads((folder / "metrics.json").read_text())
    rows = {**payload["per_sequence"], "COMBINED": payload["combined"]}
    return {name: {k: format_cell(k, v) for k, v in values.items()}
            for name, values in rows.items()}


def scorecard_rows(folder: Path) -> dict[str, dict[str, str]]:
    """The rows of the ``scorecard.md`` a scorecard wrote into ``folder``."""
    return _markdown_rows((folder / "scorecard.md").read_text())


def dry_parse(command: str) -> None:
    """Check a source's options without running it (argparse, and unitrack's own checks)."""
    words = shlex.split(command)
    if words[0] == "unitrack":
        from unitrack_env.evaluation.cli import build_parser
        from unitrack_env.evaluation.cli.common import agent_kwargs, env_kwargs

        with contextlib.redirect_stderr(io.StringIO()) as err:
            try:
                args = build_parser().parse_args(words[1:])
            except SystemExit:
                raise ValueError(f"{command}: {err.getvalue().strip().splitlines()[-1]}") \
                    from None
        if words[1] in ("evaluate", "render"):
            env_kwargs(args)
            agent_kwargs(args)
        return
    if words[0] != "python" or not (REPO / words[1]).is_file():
        raise ValueError(f"{command}: not `unitrack ...` or `python <file in the repository>`")
    _dry_parse_script(REPO / words[1], words[2:])


#: ``type=`` callables a static parser understands; any other converts to a string.
_TYPES = {"int": int, "float": float, "str": str, "Path": Path}


def _literal(node):
    """A keyword value of ``add_argument``, or None when it is not a literal."""
    import ast

    if isinstance(node, ast.Name):
        return _TYPES.get(node.id, str)
    if isinstance(node, ast.Attribute):
        return str
    try:
        return ast.literal_eval(node)
    except ValueError:
        return None


def _dry_parse_script(script: Path, args: list[str]) -> None:
    """Parse ``args`` with the script's ``add_argument`` calls, read from its source.

    Reading the calls (instead of importing the script) keeps the check to milliseconds: a
    benchmark imports torch and its whole stack before parsing anything.
    """
    import ast

    parser = argparse.ArgumentParser(prog=script.name, exit_on_error=False)
    for node in ast.walk(ast.parse(script.read_text())):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and \
                node.func.attr == "add_argument":
            names = [_literal(a) for a in node.args]
            options = {k.arg: _literal(k.value) for k in node.keywords if k.arg}
            options = {k: v for k, v in options.items() if k != "default" and v is not None}
            parser.add_argument(*names, **options)
    try:
        with contextlib.redirect_stderr(io.StringIO()) as err:
            parser.parse_args(args)
    except (argparse.ArgumentError, SystemExit) as exc:
        text = (err.getvalue().strip() or str(exc)).splitlines()[-1]
        raise ValueError(f"{script.name} {shlex.join(args)}: {text}") from None


# ------------------------------------------------------------------------------ comparing
@dataclass
class Mismatch:
    """A documented cell and the value its command printed instead."""

    figures: Figures
    row: str
    column: str
    documented: str
    replayed: str
    tolerance: float
    index: int  # the column's index in the table (0: the row names)

    def __str__(self) -> str:
        return (f"{self.figures.table.label()} row {self.row!r}, column {self.column!r}: "
                f"documented {self.documented!r}, replayed {self.replayed!r} "
                f"(tolerance {self.tolerance:g})")


def _expected(cell: Cell, row: str, column: str, outputs: dict) -> str | None:
    """The replayed text of one doc cell, or None when its source was not replayed."""
    if cell.source not in outputs:
        return None
    rows = outputs[cell.source]
    out_row = row if cell.out_row == "*" else cell.out_row
    metrics = [column if m == "*" else m for m in cell.metrics]
    if out_row not in rows:
        return f"<no row {out_row!r} in the output of ${cell.source}>"
    values = rows[out_row]
    return " / ".join(values.get(m, f"<no {m!r}>") for m in metrics)


def _same(documented: str, replayed: str, tolerance: float) -> bool:
    a, b = documented.replace("*", "").strip(), replayed.replace("*", "").strip()
    if a == b:
        return True
    numbers = [NUMBER.findall(x) for x in (a, b)]
    if not numbers[0] or len(numbers[0]) != len(numbers[1]):
        return False
    return all(abs(float(x) - float(y)) <= tolerance + 1e-9 for x, y in zip(*numbers, strict=True))


def cell_map(figures: Figures) -> dict[tuple[int, int], Cell]:
    """(row index, column index) of the table -> the cell line that sources it."""
    table, found = figures.table, {}
    for i, row in enumerate(table.rows):
        for j, column in enumerate(table.header[1:], start=1):
            for cell in figures.cells:
                if cell.row in ("*", row[0]) and cell.column in ("*", column):
                    found[(i, j)] = cell
                    break
    return found


def compare(figures: Figures, outputs: dict[int, dict]) -> list[Mismatch]:
    """Every cell whose replayed text differs from the document (replayed sources only)."""
    table, wrong = figures.table, []
    for (i, j), cell in cell_map(figures).items():
        column = table.header[j]
        if figures.skipped(column):
            continue
        expected = _expected(cell, table.rows[i][0], column, outputs)
        tolerance = figures.tolerance(column)
        if expected is not None and not _same(table.rows[i][j], expected, tolerance):
            wrong.append(Mismatch(figures, table.rows[i][0], column, table.rows[i][j],
                                  expected, tolerance, j))
    shown = {row[0] for row in table.rows}
    for cell in figures.cells:  # a whole-table cell line: the document shows every row
        if cell.row == cell.out_row == "*" and cell.source in outputs:
            wrong += [Mismatch(figures, name, "(row)", "<not in the document>", name, 0.0, 0)
                      for name in outputs[cell.source] if name not in shown]
    return wrong


def unmapped(figures: Figures) -> list[str]:
    """Numeric cells no cell line sources and no skip line excuses."""
    mapped = cell_map(figures)
    return [f"{figures.table.label()} row {row[0]!r}, column {column!r}: {row[j]!r}"
            for i, row in enumerate(figures.table.rows)
            for j, column in enumerate(figures.table.header[1:], start=1)
            if (i, j) not in mapped and not figures.skipped(column) and is_numeric(row[j])]


# ------------------------------------------------------------------------------ rewriting
def _replace_cell(line: str, j: int, new: str, box: bool) -> str:
    """``line`` with its ``j``-th cell (0 = the row name) set to ``new``, widths kept."""
    parts = re.split(f"([{BOX_CHARS}])" if box else r"((?<!\\)\|)", line.rstrip("\n"))
    segment = parts[2 + 2 * j]
    if box:
        width = max(len(segment) - 2, len(new))
        parts[2 + 2 * j] = f" {new.rjust(width)} "
    else:
        parts[2 + 2 * j] = f" {new} "
    return "".join(parts) + "\n"


def rewrite(mismatches: list[Mismatch]) -> None:
    """Write the replayed values into the documents (bold marks and box widths kept)."""
    for mismatch in mismatches:
        table = mismatch.figures.table
        path = REPO / table.doc
        lines = path.read_text().splitlines(keepends=True)
        number = next(k for k in range(table.line, len(lines))
                      if _split_row(lines[k], table.box)[:1] == [mismatch.row])
        new = mismatch.replayed.replace("*", "")
        if mismatch.documented.startswith("**"):
            new = f"**{new}**"
        lines[number] = _replace_cell(lines[number], mismatch.index, new, table.box)
        path.write_text("".join(lines))


def replay_figures(figures: Figures, kinds: set[str], work: Path, only: str = "") -> dict:
    """Run the sources replayed as one of ``kinds`` whose command contains ``only``.

    Returns their output rows by source number.
    """
    outputs = {}
    for n, command in enumerate(figures.sources, start=1):
        if figures.replay(n) in kinds and only in command:
            print(f"{figures.table.label()}: replaying ${n}: {command}", flush=True)
            folder = work / f"{figures.table.doc.replace('/', '-')}-{figures.table.line}-{n}"
            folder.mkdir(parents=True)
            outputs[n] = run_source(command, folder)
    return outputs


def main(argv: list[str] | None = None) -> int:
    """Replay every command (or those ``--only`` names), then list or rewrite what differs."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="list differences, edit nothing")
    parser.add_argument("--only", default="", help="only commands that contain this text")
    parser.add_argument("--benchmarks", action="store_true",
                        help="also replay `replay $N benchmark` sources (slow, may need network)")
    args = parser.parse_args(argv)
    kinds = {"ci", "slow", "test"} | ({"benchmark"} if args.benchmarks else set())
    found, missing = all_figures()
    for table in missing:
        print(f"{table.label()}: a table of numbers without a figures comment")
    wrong = []
    with tempfile.TemporaryDirectory() as tmp:
        for figures in found:
            wrong += compare(figures, replay_figures(figures, kinds, Path(tmp), args.only))
    for mismatch in wrong:
        print(mismatch)
    if not args.check and wrong:
        rewrite(wrong)
        print(f"rewrote {len(wrong)} cell(s)")
    return 1 if missing or (wrong and args.check) else 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    sys.exit(main())
