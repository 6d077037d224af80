"""What a run is: the environment and the agent, as workers and resumed runs rebuild them."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from typing import Any

import gymnasium as gym

import unitrack_env
from unitrack_env.agents.base import agent_class


@dataclass(frozen=True)
class RunSpec:
    """What to run: everything a worker process needs to rebuild the env and the agent.

    ``agent`` is what the user named (a registered name or a reference); ``agent_ref`` is
    the importable ``module:Class`` it resolved to, used by workers and resumed runs.
    ``repeats``: how many times each sequence is played (``--repeats``).
    """

    env_id: str
    agent: str
    agent_ref: str | None = None
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    agent_kwargs: dict[str, Any] = field(default_factory=dict)
    repeats: int = 1

    def __post_init__(self) -> None:
        if isinstance(self.repeats, bool) or not isinstance(self.repeats, int) or \
                self.repeats < 1:
            raise ValueError(f"repeats must be a whole number >= 1, not {self.repeats!r}")

    def to_json(self) -> dict[str, Any]:
        """JSON-friendly form (paths as strings); ``repeats`` only when above 1.

        So the ``run.json`` of a run without repetitions is what it was before they existed.
        """
        stored = asdict(self)
        if self.repeats == 1:
            del stored["repeats"]
        return json.loads(json.dumps(stored, default=str))

    def make_agent(self) -> Any:
        """Build the agent (by reference when there is one, so workers need no registry)."""
        return agent_class(self.agent_ref or self.agent)(**self.agent_kwargs)

    def make_env(self) -> gym.Env:
        """Build the environment."""
        unitrack_env.register_all()
        return gym.make(self.env_id, **self.env_kwargs)
