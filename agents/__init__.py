"""Reference agents for unitrack-env: the UniTrack heads and simple baselines.

>>> from unitrack_env.agents import make_agent
>>> agent = make_agent("iou")
>>> type(agent).__name__
'IoUAgent'
"""

from .base import (
    AGENTS,
    Agent,
    agent_class,
    agents_for_task,
    available_agents,
    make_agent,
)

__all__ = ["AGENTS", "Agent", "agent_class", "agents_for_task", "available_agents", "make_agent"]
