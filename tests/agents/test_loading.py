"""Agents by reference, by plug-in entry point, and their typed options."""

from __future__ import annotations

import sys
import textwrap
from typing import Literal

import pytest

from unitrack_env.agents import Agent, agent_class, available_agents, make_agent
from unitrack_env.agents.base import AGENTS
from unitrack_env.agents.loading import agent_reference, is_reference, portable_reference
from unitrack_env.agents.options import (
    AgentOptionError,
    agent_options,
    check_options,
    conforms,
    parse_options,
)

TRACKER = textwrap.dedent('''
    from unitrack_env.agents import Agent

    class FileTracker(Agent, tasks=("mot",)):
        def __init__(self, gate: float = 0.5, name_of_run: str = "x"):
            self.gate = gate
        def reset(self, observation, info):
            pass
        def act(self, observation):
            return {}
''')


BASE = textwrap.dedent('''
    from unitrack_env.agents import Agent

    class Base(Agent, tasks=("mot",)):
        def reset(self, observation, info):
            pass
        def act(self, observation):
            return {}
''')


@pytest.fixture(autouse=True)
def _restore_sys_path(monkeypatch):
    """Loading a user's agent puts its folder on ``sys.path``; undo that after each test."""
    monkeypatch.setattr(sys, "path", list(sys.path))


def test_reference_spellings():
    assert is_reference("pkg.mod:Class") and is_reference("dir/file.py:Class")
    assert is_reference("C:/trackers/file.py:Class")
    assert not is_reference("iou") and not is_reference("unitrack-vos")
    assert agent_class("unitrack_env.agents.baselines.iou:IoUAgent") is agent_class("iou")


def test_file_reference_and_its_portable_form(tmp_path):
    path = tmp_path / "trackers.py"
    path.write_text(TRACKER)
    cls = agent_class(f"{path}:FileTracker")
    assert cls.__name__ == "FileTracker" and make_agent(f"{path}:FileTracker", gate=0.7).gate == 0.7
    assert agent_reference(cls) == f"{path}:FileTracker"
    assert portable_reference(cls) == f"{path}:FileTracker"


def test_module_reference_from_the_current_folder(tmp_path, monkeypatch):
    (tmp_path / "cwd_trackers.py").write_text(TRACKER)
    monkeypatch.chdir(tmp_path)
    monkeypatch.delitem(sys.modules, "cwd_trackers", raising=False)
    cls = agent_class("cwd_trackers:FileTracker")
    assert cls.__module__ == "cwd_trackers"
    assert portable_reference(cls) == "cwd_trackers:FileTracker"


def test_a_file_agent_imports_the_files_beside_it(tmp_path):
    # As `python file.py` would: the file's folder first on sys.path.
    (tmp_path / "beside_file_base.py").write_text(BASE)
    (tmp_path / "file_agent.py").write_text("from beside_file_base import Base\n"
                                            "class Mine(Base):\n    pass\n")
    assert agent_class(f"{tmp_path / 'file_agent.py'}:Mine").__mro__[1].__name__ == "Base"


def test_a_module_agent_imports_the_files_beside_it(tmp_path, monkeypatch):
    # As `python -m module_agent` would: the current folder first on sys.path.
    (tmp_path / "beside_module_base.py").write_text(BASE)
    (tmp_path / "module_agent.py").write_text("from beside_module_base import Base\n"
                                              "class Mine(Base):\n    pass\n")
    monkeypatch.chdir(tmp_path)
    assert agent_class("module_agent:Mine").__module__ == "module_agent"


def test_a_file_agent_whose_import_fails_is_named(tmp_path):
    (tmp_path / "broken_agent.py").write_text("import no_such_helper_xyz\n")
    with pytest.raises(ImportError, match="agent file .*broken_agent.py: No module named "
                                          "'no_such_helper_xyz'"):
        agent_class(f"{tmp_path / 'broken_agent.py'}:Mine")


def _clash(tmp_path, monkeypatch):
    """An installed top-level ``clashing_pkg`` (as openai-agents ships ``agents``) and the
    user's own ``clashing_pkg/`` with a tracker, in the current folder."""
    site = tmp_path / "site"
    (site / "clashing_pkg").mkdir(parents=True)
    (site / "clashing_pkg" / "__init__.py").write_text('"""installed"""\n')
    project = tmp_path / "project"
    (project / "clashing_pkg").mkdir(parents=True)
    (project / "clashing_pkg" / "__init__.py").write_text('"""the user own"""\n')
    (project / "clashing_pkg" / "mine.py").write_text(TRACKER)
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.chdir(project)
    for name in ("clashing_pkg", "clashing_pkg.mine"):
        monkeypatch.delitem(sys.modules, name, raising=False)
    return site, project


def test_the_current_folder_comes_first_as_with_python_m(tmp_path, monkeypatch):
    _, project = _clash(tmp_path, monkeypatch)
    cls = agent_class("clashing_pkg.mine:FileTracker")
    assert sys.modules["clashing_pkg"].__file__.startswith(str(project))
    assert cls.__module__ == "clashing_pkg.mine"


def test_an_installed_package_already_imported_is_named_when_it_hides_the_users(
        tmp_path, monkeypatch):
    site, _ = _clash(tmp_path, monkeypatch)
    import clashing_pkg  # noqa: F401  (imported by something else first)

    with pytest.raises(ImportError, match="already imported from .*site.*hides ./clashing_pkg; "
                                          "name the file instead"):
        agent_class("clashing_pkg.mine:FileTracker")


@pytest.mark.parametrize(("spec", "message"), [
    ("no_such_module_xyz:Tracker", "cannot import module 'no_such_module_xyz'"),
    ("unitrack_env.agents.baselines.iou:Nope", "has no attribute 'Nope'"),
    ("unitrack_env.envs.motchallenge:DEFAULT_MAX_TRACKS", "is not a class"),
    ("unitrack_env.spaces:Image", r"no reset\(observation, info\)"),
    ("/nonexistent/file.py:Tracker", "does not exist"),
])
def test_bad_references_say_what_is_wrong(spec, message):
    with pytest.raises((ImportError, FileNotFoundError), match=message):
        agent_class(spec)


def test_unknown_name_lists_the_known_ones():
    with pytest.raises(KeyError, match="available: .*iou.*module:ClassName"):
        agent_class("no-such-agent")


@pytest.mark.parametrize(("name", "hint"), [("unitrak", "did you mean unitrack"),
                                            ("IoU", "did you mean iou?")])
def test_a_mistyped_name_gets_the_closest_ones(name, hint):
    with pytest.raises(KeyError, match=hint):  # issue 42: only the list, as for env ids
        agent_class(name)


def test_a_mistyped_class_gets_the_classes_of_its_file(tmp_path):
    path = tmp_path / "mytracker.py"
    path.write_text(TRACKER.replace("FileTracker", "GreedyIoU"))
    with pytest.raises(ImportError, match="no attribute 'GreedyIou'; did you mean GreedyIoU"):
        agent_class(f"{path}:GreedyIou")
    with pytest.raises(ImportError, match="no attribute 'Zzz'$"):  # nothing close: no hint
        agent_class(f"{path}:Zzz")


def test_interactive_classes_are_not_portable():
    namespace: dict = {}
    exec(TRACKER.replace("FileTracker", "ExecTracker"), namespace)
    assert portable_reference(namespace["ExecTracker"]) is None

    def local():
        class Local(Agent):
            def reset(self, observation, info): ...
            def act(self, observation): ...
        return Local

    assert portable_reference(local()) is None


def test_plugins_from_the_entry_point_group(tmp_path, monkeypatch):
    (tmp_path / "plugin_trackers.py").write_text(TRACKER)
    info = tmp_path / "plugin_trackers-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: plugin-trackers\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(
        "[unitrack_env.agents]\nplugin-tracker = plugin_trackers:FileTracker\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        assert "plugin-tracker" in available_agents()
        assert agent_class("plugin-tracker").__name__ == "FileTracker"
    finally:
        AGENTS.pop("plugin-tracker", None)


def test_options_of_config_dataclass_agents():
    options = agent_options(agent_class("iou"))
    assert options["min_hits"] is int and options["iou_threshold"] is float
    assert "**" not in options  # IoUConfig's fields are the whole set
    with pytest.raises(AgentOptionError, match="has no option 'min_hit'.*min_hits \\(int\\)"):
        check_options(agent_class("iou"), {"min_hit": 3})
    with pytest.raises(AgentOptionError, match="'min_hits' must be int, got 2.5"):
        check_options(agent_class("iou"), {"min_hits": 2.5})
    check_options(agent_class("iou"), {"min_hits": 3, "iou_threshold": 1})  # int is a float


def test_option_values_are_checked_by_the_config_before_anything_is_built():
    # The config's own checks run in check_options (the runner's one check before a run),
    # not first in a worker building the agent.
    with pytest.raises(AgentOptionError, match=r"'unitrack': UniTrackConfig.duplicate_iou must "
                                               r"be in \[0, 1\], got 1.5"):
        check_options(agent_class("unitrack"), {"duplicate_iou": 1.5, "max_tracks": 5})
    with pytest.raises(AgentOptionError, match="'unitrack-vos': memory_size must be >= 1"):
        check_options(agent_class("unitrack-vos"), {"memory_size": 0})
    check_options(agent_class("unitrack"), {"preset": "paper", "gate": False})


def test_cli_values_are_parsed_by_type():
    unitrack = agent_class("unitrack")
    parsed = parse_options(unitrack, ["weights=moco.pth", "input_size=(320, 192)",
                                      "use-motion=False", "layer=stage3+stage5"])
    assert parsed == {"weights": "moco.pth", "input_size": (320, 192), "use_motion": False,
                      "layer": "stage3+stage5"}
    with pytest.raises(AgentOptionError, match="must look like key=value"):
        parse_options(unitrack, ["weights"])
    with pytest.raises(AgentOptionError, match="'use_motion' must be bool"):
        parse_options(unitrack, ["use_motion=maybe"])


def test_conforms_understands_common_annotations():
    assert conforms(None, int | None) and conforms(3, int | None) and not conforms("3", int)
    assert conforms("rsm", Literal["rsm", "cf"]) and not conforms("x", Literal["rsm", "cf"])
    assert conforms((1, 2), tuple[int, int]) and not conforms((1, 2, 3), tuple[int, int])
    assert conforms([1.0, 2], list[float]) and not conforms(True, float)
