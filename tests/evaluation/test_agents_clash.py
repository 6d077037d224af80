from __future__ import annotations

import sys
import types

import pytest

from evaluation._agents import agents_module


def test_unitrack_agents_package_is_recognised():
    assert agents_module().UNITRACK_AGENTS is True


def test_a_foreign_agents_package_is_explained(monkeypatch):
    foreign = types.ModuleType("agents")
    foreign.__file__ = "/site-packages/agents/__init__.py"
    monkeypatch.setitem(sys.modules, "agents", foreign)
    with pytest.raises(ImportError, match="openai-agents.*separate virtual environment"):
        agents_module()
