"""The agent interface and the registry of agents by name.

An agent is one class with two methods::

    class MyTracker(Agent, name="my-tracker", tasks=("mot",)):
        def reset(self, observation, info): ...
        def act(self, observation): ...   # returns the environment's action

Subclassing registers it; ``make_agent("my-tracker", **kwargs)`` builds it. Built-ins are
imported lazily; others are named ``"module:Class"`` / ``"file.py:Class"`` or published in
the ``unitrack_env.agents`` entry-point group (:mod:`unitrack_env.agents.loading`).
"""

from __future__ import annotations

import abc
import importlib
from typing import Any, ClassVar

from .loading import did_you_mean, entry_point_agents, is_reference, load_reference

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
    "static-points": "unitrack_env.agents.baselines.static_points",
    "lk-points": "unitrack_env.agents.baselines.lucas_kanade",
    "unitrack-points": "unitrack_env.agents.heads.points",
}


class Agent(abc.ABC):
    """A tracker that plays episodes; class keywords ``name=`` (registry) and ``tasks=``."""

    name: ClassVar[str] = ""
    tasks: ClassVar[tuple[str, ...]] = ()
    #: The dataclass that collects the agent's ``**options`` (its fields are the options the
    #: CLI's ``--agent-arg`` checks by name and type), or None when ``__init__`` says it all.
    config_class: ClassVar[type | None] = None

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


def close_agent(agent: Any) -> None:
    """Call ``agent.close()`` when it has one (a duck-typed agent need not)."""
    close = getattr(agent, "close", None)
    if callable(close):
        close()


def available_agents() -> list[str]:
    """Return the names of all known agents (built-in, registered and installed plug-ins)."""
    return sorted(set(AGENTS) | set(_BUILTIN_MODULES) | set(entry_point_agents()))


def _is_agent_class(cls: type) -> bool:
    return issubclass(cls, Agent) or (callable(getattr(cls, "reset", None))
                                      and callable(getattr(cls, "act", None)))


def agent_class(spec: str | type) -> type[Agent]:
    """Return the agent class named by ``spec``: a name, a ``module:Class`` reference, or a class.

    Unknown names raise KeyError (listing the known), bad references ImportError, other
    objects TypeError.
    """
    if isinstance(spec, type):
        if not _is_agent_class(spec):
            raise TypeError(f"{spec.__name__} has no reset(observation, info) and "
                            "act(observation) methods")
        return spec
    if not isinstance(spec, str):
        got = (f"an instance of {type(spec).__name__}" if _is_agent_class(type(spec))
               else repr(spec))
        raise TypeError(
            f"an agent is named by a name, 'module:Class', 'path/to/file.py:Class' or the "
            f"class itself; got {got} (pass its class, and its options as keyword arguments "
            "or agent_kwargs)")
    if is_reference(spec):
        cls = load_reference(spec)
        if not _is_agent_class(cls):
            raise ImportError(f"agent '{spec}' has no reset(observation, info) and "
                              "act(observation) methods")
        return cls
    if spec not in AGENTS and spec in _BUILTIN_MODULES:
        importlib.import_module(_BUILTIN_MODULES[spec])
    if spec not in AGENTS:
        plugin = entry_point_agents().get(spec)
        if plugin is not None:
            cls = plugin.load()
            AGENTS.setdefault(spec, cls)
            return cls
    try:
        return AGENTS[spec]
    except KeyError:
        raise KeyError(
            f"unknown agent '{spec}'; {did_you_mean(spec, available_agents())}"
            f"available: {', '.join(available_agents())} (or name "
            "one by reference: 'package.module:ClassName' or 'path/to/file.py:ClassName')"
        ) from None


def agents_for_task(task: str) -> list[str]:
    """Names of the known agents that declare ``task`` (imports the built-in modules)."""
    fitting = []
    for name in available_agents():
        try:
            cls = agent_class(name)
        except (ImportError, KeyError):
            continue
        if task in getattr(cls, "tasks", ()):
            fitting.append(name)
    return fitting


def make_agent(spec: str | type, **kwargs: Any) -> Agent:
    """Build the agent named by ``spec`` (see :func:`agent_class`) with keyword arguments."""
    return agent_class(spec)(**kwargs)
