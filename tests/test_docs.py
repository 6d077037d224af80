"""The generated environment pages are up to date, and the README's promises hold."""

from __future__ import annotations

import contextlib
import importlib.util
import json
import re
import shlex
import sys
from pathlib import Path

import gymnasium as gym

REPO = Path(__file__).resolve().parents[1]


def test_env_pages_match_docstrings():
    spec = importlib.util.spec_from_file_location("make_env_docs",
                                                  REPO / "scripts" / "make_env_docs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    for name, text in module.pages().items():
        page = REPO / "docs" / "envs" / name
        assert page.is_file(), f"{page} missing: run python scripts/make_env_docs.py"
        assert page.read_text() == text, f"{page} is stale: run python scripts/make_env_docs.py"
        assert not re.search(r":[a-z]+:`", text), f"{page} shows Sphinx markup"  # issue 42
    assert module.plain_markdown(":class:`~a.b.Image` and :mod:`a.b`") == "`Image` and `a.b`"


def test_readme_has_exactly_two_setup_commands_and_ci_runs_the_test_one():
    readme = (REPO / "README.md").read_text()
    setup = readme.split("## Set up", 1)[1].split("\n## ", 1)[0]
    commands = [line for line in re.findall(r"```bash\n(.*?)```", setup, re.S)[0].splitlines()
                if line.strip() and not line.startswith("#")]
    assert len(commands) == 2
    ci = (REPO / ".ci" / "run").read_text()
    assert commands[1] in ci


def test_readme_says_to_activate_the_venv_before_its_first_bare_command():
    readme = (REPO / "README.md").read_text()  # issue 42: copied as printed: not found
    first_bare = min(readme.index(f"\n{word} ") for word in ("unitrack", "python")
                     if f"\n{word} " in readme)
    assert "source .venv/bin/activate" in readme[:first_bare]
    setup = readme.split("## Set up", 1)[1].split("\n## ", 1)[0]
    assert re.search(r"\d+ s on a quiet\s+2-core machine", setup)  # how long the tests take


def test_writing_an_agent_describes_the_observation_and_links_the_env_pages():
    text = (REPO / "docs" / "writing-an-agent.md").read_text()  # issue 42
    assert 'observation["frame"]' in text and "uint8 RGB" in text and "(H, W, 3)" in text
    assert "`max_tracks` is" in text
    linked = set(re.findall(r"\]\(envs/([\w-]+\.md)\)", text))
    assert linked == {p.name for p in (REPO / "docs" / "envs").glob("*.md")}


def _anchor(heading: str) -> str:
    """GitHub's anchor of a markdown heading: lower case, punctuation dropped, spaces to -."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_readme_links_exist():
    readme = (REPO / "README.md").read_text()
    for link in re.findall(r"\]\(((?:docs|benchmarks)/[^)]+)\)", readme):
        path, _, anchor = link.partition("#")
        assert (REPO / path).exists(), link
        if anchor:
            headings = re.findall(r"^#+ (.+)$", (REPO / path).read_text(), re.M)
            assert anchor in {_anchor(h) for h in headings}, link


def _python_blocks(path: Path) -> list[str]:
    return re.findall(r"```python\n(.*?)```", path.read_text(), re.S)


def test_readme_quickstart_runs(capsys):
    code = _python_blocks(REPO / "README.md")[0]
    exec(compile(code, "README.md", "exec"), {})
    printed = capsys.readouterr().out.split()
    assert len(printed) == 3 and all(0.0 <= float(x) <= 1.0 for x in printed)


def test_writing_an_agent_example_runs():
    from unitrack_env.agents.base import AGENTS
    from unitrack_env.evaluation.run.runner import run

    code = _python_blocks(REPO / "docs" / "writing-an-agent.md")[0]
    try:
        exec(compile(code, "writing-an-agent.md", "exec"), {})
        import tempfile

        with tempfile.TemporaryDirectory() as out:
            report = run("UniTrack/MOT16-v0", "nearest-centre", out=out, progress=False)
        assert 0 < report.combined["IDF1"] <= 1
    finally:
        AGENTS.pop("nearest-centre", None)


def _titled_blocks(path: Path) -> dict[str, str]:
    """The code blocks titled with a file name: ```` ```python title="name.py" ````."""
    return dict(re.findall(r'```python title="([^"]+)"\n(.*?)```', path.read_text(), re.S))


def test_adding_a_tracker_example_runs(tmp_path, monkeypatch, capsys):
    """The tracker of adding-a-task.md (adapter + Associator) plays boxes and masks."""
    from unitrack_env.agents.base import AGENTS
    from unitrack_env.evaluation.cli import main

    doc = REPO / "docs" / "adding-a-task.md"
    (tmp_path / "colour_tracker.py").write_text(_titled_blocks(doc)["colour_tracker.py"])
    block = next(b for b in re.findall(r"```bash\n(.*?)```", doc.read_text(), re.S)
                 if "colour_tracker.py" in b)
    commands = [shlex.split(line) for line in block.splitlines() if line.strip()]
    assert {c[c.index("--env") + 1] for c in commands} == {"UniTrack/MOT17-v0",
                                                           "UniTrack/MOTS-v0"}
    monkeypatch.chdir(tmp_path)
    try:
        for command in commands:
            assert command[:2] == ["unitrack", "evaluate"]
            capsys.readouterr()
            assert main([*command[1:], "--format", "json", "--quiet"]) == 0
            combined = json.loads(capsys.readouterr().out)["combined"]
            assert combined["IDF1"] > 0.5, (command, combined)
    finally:
        AGENTS.pop("colour", None)


def test_adding_a_task_quotes_the_mean_error_its_commands_print(tmp_path, monkeypatch, capsys):
    """The one figure in adding-a-task.md's prose is what the doc's own commands print."""
    import test_adding_a_task as doc  # tests/ is on sys.path (pytest's default import mode)

    sentence = re.search(r"so (\S+)'s mean error of\s+([\d.]+) px reads ([\d.]+)",
                         doc.DOC.read_text())
    assert sentence, "adding-a-task.md no longer quotes a mean error: update this test"
    sequence, error, shown = sentence.groups()
    with contextlib.ExitStack() as stack:
        stack.callback(lambda: [sys.modules.pop(m) for m in list(sys.modules)
                                if m.split(".")[0] == "centroid_task"])
        stack.callback(gym.registry.pop, doc.ENV_ID, None)
        monkeypatch.setattr(doc.registration, "_ADDED", [])
        folder = tmp_path / "project"
        for name in doc.PROJECT_FILES:
            (folder / name).parent.mkdir(parents=True, exist_ok=True)
            (folder / name).write_text(doc.doc_files()[name])
        monkeypatch.chdir(folder)
        monkeypatch.syspath_prepend(str(folder))
        commands = doc.doc_commands()
        doc.run_command(commands["data"], monkeypatch)
        capsys.readouterr()
        doc.run_command(commands["evaluate"], monkeypatch, "--format", "json")
        value = json.loads(capsys.readouterr().out)["per_sequence"][sequence]["MeanError"]
    assert f"{value:.{len(error.split('.')[1])}f}" == error
    assert f"{100 * value:.1f}" == shown  # the table's percent rule


def test_architecture_lists_the_public_api():
    """docs/architecture.md's public API table names exactly each package's ``__all__``."""
    text = (REPO / "docs" / "architecture.md").read_text()
    section = text.split("## Public API")[1].split("\n## ")[0]
    rows = re.findall(r"^\| `([\w.]+)` \| (.*) \|$", section, flags=re.M)
    assert len(rows) >= 7
    for package, names in rows:
        exported = set(importlib.import_module(package).__all__)
        assert set(re.findall(r"`(\w+)`", names)) == exported, package
