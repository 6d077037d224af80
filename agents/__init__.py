"""Reference agents for unitrack-env: the UniTrack heads and simple baselines.

>>> from agents import make_agent
>>> agent = make_agent("iou")
>>> type(agent).__name__
'IoUAgent'
"""

from agents.base import AGENTS, Agent, available_agents, make_agent

#: Marker checked by ``evaluation`` to detect another distribution's top-level ``agents``
#: package (e.g. ``openai-agents``) shadowing this one.
UNITRACK_AGENTS = True

__all__ = ["AGENTS", "Agent", "UNITRACK_AGENTS", "available_agents", "make_agent"]
