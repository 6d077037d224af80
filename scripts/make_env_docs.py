"""Write docs/envs/<page>.md from the environments' class docstrings (one page per env class).

Run after changing an environment's docstring: ``python scripts/make_env_docs.py``.
A test fails when a page is out of date.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import re
import sys
from pathlib import Path

import unitrack_env

DOCS = Path(__file__).resolve().parents[1] / "docs" / "envs"
#: A Sphinx cross-reference in a docstring (``:class:`~pkg.Name```, ``:meth:`name```, ...).
SPHINX_ROLE = re.compile(r":(?:class|data|func|meth|mod|attr|obj|exc):`(~?)([^`]+)`")


def plain_markdown(text: str) -> str:
    """Sphinx roles as Markdown code, e.g. ``:class:`~a.B``` -> `` `B` ``."""
    return SPHINX_ROLE.sub(lambda m: f"`{m[2].rsplit('.', 1)[-1] if m[1] else m[2]}`", text)


def pages() -> dict[str, str]:
    """Return ``{file name: markdown}`` for every environment class in the registry table."""
    by_class: dict[str, list[str]] = {}
    for variant in unitrack_env.VARIANTS:
        by_class.setdefault(variant.entry_point, []).append(variant.env_id)
    out = {}
    for entry_point, ids in by_class.items():
        module_name, class_name = entry_point.split(":")
        cls = getattr(importlib.import_module(module_name), class_name)
        doc = inspect.cleandoc(cls.__doc__ or "")
        summary, _, body = doc.partition("\n")
        task = module_name.rsplit(".", 1)[-1]
        header = f"# {summary.strip()}\n\nIds: " + ", ".join(f"`{i}`" for i in ids) + "\n"
        note = (f"\n<!-- generated from {module_name}.{class_name} by "
                "scripts/make_env_docs.py; edit the docstring, not this file -->\n")
        out[f"{task}.md"] = (header + note + plain_markdown(body.rstrip()) + "\n"
                             + _score_table(ids))
    return out


def _score_table(ids: list[str]) -> str:
    """The declared detection score range of each id (``unitrack_env.score_range``), if any."""
    rows = []
    for variant in unitrack_env.VARIANTS:
        scores = variant.detection_scores
        if variant.env_id in ids and scores is not None:
            custom = " (custom data: the rule set's range unless `score_range=`)" \
                if variant.folder is None else ""
            rows.append(f"| `{variant.env_id}` | {scores.low:g} .. {scores.high:g} | "
                        f"{'yes' if scores.bounded else 'no'} | {scores.source}{custom} |")
    if not rows:
        return ""
    return ("\n## Detection scores\n\nThe range each id declares for its detection scores "
            "(reported as `info[\"detection_scores\"]` at reset; agents state thresholds on "
            "0..1 of it), from `unitrack_env.score_range.DETECTION_SCORES`:\n\n"
            "| id | range | bounded | source |\n|---|---|---|---|\n" + "\n".join(rows) + "\n")


def main() -> int:
    """Write every page."""
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    DOCS.mkdir(parents=True, exist_ok=True)
    for name, text in pages().items():
        (DOCS / name).write_text(text)
        print(f"wrote {DOCS / name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
