"""Which source files count as an agent's code (the run identity holds their content)."""

from __future__ import annotations

from pathlib import Path

import unitrack_env.agents.baselines.iou  # noqa: F401  (module references resolve once imported)
import unitrack_env.agents.heads.association  # noqa: F401
import unitrack_env.agents.heads.sot  # noqa: F401
from unitrack_env.evaluation.run.agent_code import agent_code, code_manifest


def _names(paths: list[Path]) -> set[str]:
    return {f"{p.parent.name}/{p.name}" for p in paths}


def test_a_head_counts_its_primitives_and_the_appearance_model():
    code = _names(agent_code("unitrack_env.agents.heads.sot:UniTrackXCorrAgent"))
    assert {"heads/sot.py", "primitives/box_propagation.py", "appearance/model.py",
            "appearance/vit.py", "appearance/resnet.py", "agents/base.py"} <= code
    assert not any(name.startswith(("envs/", "metrics/", "evaluation/")) for name in code)


def test_other_modules_of_the_package_count_one_import_away_and_are_not_followed():
    """geometry's IoU or an environment's track cap decide actions too; what those modules
    import (the environment's readers) does not."""
    names = set(code_manifest("unitrack_env.agents.heads.association:UniTrackAgent"))
    assert {"unitrack_env/agents/heads/association.py", "unitrack_env/geometry.py",
            "unitrack_env/envs/motchallenge.py"} <= names
    assert "unitrack_env/envs/base.py" not in names
    assert not any(name.startswith(("unitrack_env/metrics/", "unitrack_env/evaluation/"))
                   for name in names)


def test_a_baseline_counts_only_what_it_imports():
    code = _names(agent_code("unitrack_env.agents.baselines.iou:IoUAgent"))
    assert "baselines/iou.py" in code and "primitives/overlap.py" in code
    assert not any(name.startswith("appearance/") for name in code)


def test_an_agent_file_counts_its_relative_and_sibling_imports_and_nothing_installed(tmp_path):
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "__init__.py").write_text("")
    (tmp_path / "pkg" / "agent.py").write_text(
        "import numpy\nfrom . import tools\nfrom .more import thing\nimport helper\n"
        "from pkg.sub.absolute import y\n"
        "from unitrack_env.agents.baselines.iou import IoUAgent\n"
        "class Mine(IoUAgent):\n    pass\n")
    (tmp_path / "pkg" / "tools.py").write_text("from .deep import x\n")
    (tmp_path / "pkg" / "deep.py").write_text("x = 1\n")
    (tmp_path / "pkg" / "more.py").write_text("thing = 2\n")
    (tmp_path / "pkg" / "helper.py").write_text("import helper\n")  # imports itself: no loop
    (tmp_path / "pkg" / "unused.py").write_text("")
    (tmp_path / "pkg" / "sub").mkdir()
    (tmp_path / "pkg" / "sub" / "__init__.py").write_text("")
    (tmp_path / "pkg" / "sub" / "absolute.py").write_text("y = 3\n")
    code = _names(agent_code(f"{tmp_path / 'pkg' / 'agent.py'}:Mine"))
    assert {"pkg/agent.py", "pkg/tools.py", "pkg/deep.py", "pkg/more.py",
            "pkg/helper.py", "sub/absolute.py", "baselines/iou.py"} <= code
    assert "pkg/unused.py" not in code and not any("numpy" in name for name in code)


def test_a_reference_without_a_file_has_no_code(tmp_path):
    assert agent_code("no_such_module:Agent") == []
    assert agent_code(f"{tmp_path / 'missing.py'}:Agent") == []
    (tmp_path / "broken.py").write_text("def (:\n")  # unparsable: its own bytes still count
    assert _names(agent_code(f"{tmp_path / 'broken.py'}:Agent")) == {f"{tmp_path.name}/broken.py"}
