"""The agent interface and the registry of agents by name.

An agent is one class with two methods::

    class MyTracker(Agent, name="my-tracker", tasks=("mot",)):
        def reset(self, observation, info): ...
        def act(self, observation): ...   # returns the environment's action

Subclassing registers the class under ``name``; ``make_agent("my-tracker", **kwargs)``
builds it. Built-in agents are imported lazily on first use so that ``import unitrack_env.agents``
stays cheap (no torch import for the IoU baseline).
"""

from __future__ import annotations

import abc
import importlib
from typing import Any, ClassVar

#: Registered agent classes by name (built-ins appear once their module is imported).
AGENTS: dict[str, type[Agent]] = {}

#: Built-in agents and the module that defines each one.
_BUILTIN_MODULES: dict[str, str] = {
    "iou": "unitrack_env.agents.baselines.iou",
    "fresh-ids": "unitrack_env.agents.baselines.trivial",
    "unitrack": "unitrack_env.agents.heads.association",
    "repeat-box": "unitrack_env.agents.baselines.repeat",
    "repeat-mask": "unitrack_env.agents.baselines.repeat",
    "repeat-pose": "unitrack_env.agents.baselines.repeat_pose",
    "unitrack-xcorr": "unitrack_env.agents.heads.sot",
    "unitrack-dcf": "unitrack_env.agents.heads.sot",
    "unitrack-vos": "unitrack_env.agents.heads.vos",
    "unitrack-pose": "unitrack_env.agents.heads.pose",
}


class Agent(abc.ABC):
    """A tracker that plays episodes of unitrack environments.

    Class attributes:
        name: registry name (set by the ``name=`` class keyword).
        tasks: task families it can play (``"mot"``, ...), see ``unitrack_env.task_of``.
    """

    name: ClassVar[str] = ""
    tasks: ClassVar[tuple[str, ...]] = ()

    def __init_subclass__(cls, name: str | None = None, tasks: tuple[str, ...] = (),
                          **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if name is not None:
            existing = AGENTS.get(name)
            if existing is not None and existing.__qualname__ != cls.__qualname__:
                raise ValueError(f"agent name '{name}' is already taken by {existing.__qualname__}")
            cls.name = name
            cls.tasks = tuple(tasks)
            AGENTS[name] = cls

    @abc.abstractmethod
    def reset(self, observation: Any, info: dict[str, Any]) -> None:
        """Start a new episode; forget every track and id from the previous one."""

    @abc.abstractmethod
    def act(self, observation: Any) -> Any:
        """Return the action (the tracks) for the frame in ``observation``."""

    def close(self) -> None:  # noqa: B027 - optional hook, empty by default
        """Release resources (threads, files); optional."""


def available_agents() -> list[str]:
    """Return the names of all known agents (built-in and registered)."""
    return sorted(set(AGENTS) | set(_BUILTIN_MODULES))


def agent_class(name: str) -> type[Agent]:
    """Return the class registered under ``name``, importing built-ins on demand."""
    if name not in AGENTS and name in _BUILTIN_MODULES:
        importlib.import_module(_BUILTIN_MODULES[name])
    try:
        return AGENTS[name]
    except KeyError:
        raise KeyError(
            f"unknown agent '{name}'; available: {', '.join(available_agents())}"
        ) from None


def make_agent(name: str, **kwargs: Any) -> Agent:
    """Build the agent registered under ``name`` with keyword arguments."""
    return agent_class(name)(**kwargs)
