"""Committed scorecards (docs/results/): their documented tables come from their stored cells.

Some cards take hours on a laptop (a ViT-B/8 plays one OTB clip in 45 minutes), so the
repository keeps their cells; the documented command, rerun with the same ``--out``, resumes
from them. This test checks that the committed folder holds every cell the command needs and
that scoring them again prints the documented table (nothing is played): a cell missing, or
stale because the data or the agents' code changed, fails here in seconds instead of being
played for hours.
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

import pytest

from unitrack_env.evaluation.cli import build_parser
from unitrack_env.evaluation.scorecard.card import cells_to_play
from unitrack_env.evaluation.scorecard.plan import TASKS, ModelSpec, plan

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tests"))
from test_doc_figures import FOUND, load_figures  # noqa: E402  (tests/ is not a package)

doc_figures = load_figures()
COMMITTED = [pytest.param(figures, n, id=f"{figures.table.label()}-${n}")
             for figures in FOUND for n, command in enumerate(figures.sources, start=1)
             if doc_figures.committed_card(command) is not None]


def test_committed_cards_are_documented():
    """Every folder under docs/results/ is the --out of a documented command (none orphaned)."""
    documented = {doc_figures.committed_card(figures.sources[n - 1])
                  for figures, n in (p.values for p in COMMITTED)}
    folders = {p for p in (REPO / doc_figures.RESULTS).iterdir() if p.is_dir()} \
        if (REPO / doc_figures.RESULTS).is_dir() else set()
    assert folders <= documented, f"undocumented result folders: {sorted(folders - documented)}"
    for figures, n in (p.values for p in COMMITTED):
        assert figures.replay(n) == "test", (f"{figures.table.label()}: a committed card is "
                                             "replayed by this file's test (replay $N test ...)")
        assert figures.replayed_by(n).endswith("::test_committed_scorecard_replays_its_table")


@pytest.mark.slow
@pytest.mark.parametrize(("figures", "n"), COMMITTED)
def test_committed_scorecard_replays_its_table(figures, n, shared_data, tmp_path):
    command = figures.sources[n - 1]
    card = doc_figures.committed_card(command)
    args = build_parser().parse_args(shlex.split(command)[1:])
    models = [ModelSpec.parse(text) for text in args.model]
    cells, _, _ = plan(models, args.tasks.split(",") if args.tasks else list(TASKS),
                       (REPO / args.data).resolve(), motion=args.motion, runtime=args.runtime)
    missing = [cell.label for cell in cells_to_play(card, cells)]
    assert not missing, (f"{card.relative_to(REPO)} lacks {len(missing)} cells of `{command}`, "
                         "or its stored cells are stale (their data or the agents' code changed): "
                         "run it from the repository root to play them, or, for an edit that "
                         "cannot move a number, add --restamp to keep them (it checks that the "
                         f"code is all that changed and names the files): {missing}")
    wrong = doc_figures.compare(figures, {n: doc_figures.run_source(command, tmp_path)})
    assert not wrong, (f"documented cells differ from the stored cells of `{command}`:\n"
                       + "\n".join(map(str, wrong)))
