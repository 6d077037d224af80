"""``unitrack list``: the environments and agents (with the plug-ins')."""

from __future__ import annotations

import argparse

from rich.console import Console
from rich.table import Table

from unitrack_env.agents.base import agent_class, available_agents
from unitrack_env.agents.loading import entry_point_agents
from unitrack_env.registration import variants


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``unitrack list`` has no options."""


def run(args: argparse.Namespace, console: Console) -> int:
    """Run ``unitrack list``."""
    envs = Table(title="environments", title_justify="left")
    envs.add_column("id", no_wrap=True)
    envs.add_column("task")
    for variant in variants():
        envs.add_row(variant.env_id, variant.task)
    console.print(envs)
    plugins = entry_point_agents()
    agents = Table(title="agents (--agent NAME, or module:Class, or file.py:Class)",
                   title_justify="left")
    for column in ("name", "tasks", "from"):
        agents.add_column(column, no_wrap=column == "name")
    for name in available_agents():
        try:
            tasks = ", ".join(getattr(agent_class(name), "tasks", ()))
        except Exception as exc:  # a broken plug-in must not hide the others
            tasks = f"(cannot load: {type(exc).__name__})"
        source = f"plug-in {plugins[name].value}" if name in plugins else "unitrack-env"
        agents.add_row(name, tasks, source)
    console.print(agents)
    return 0
