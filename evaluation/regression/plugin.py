"""pytest plugin: the ``episode_regression`` fixture and the ``--update-goldens`` flag."""

from __future__ import annotations

from typing import Any

import pytest

from unitrack_env.evaluation.regression.golden import EpisodeRecord, check_episode


def pytest_addoption(parser: pytest.Parser) -> None:
    """Add ``--update-goldens``."""
    group = parser.getgroup("unitrack")
    group.addoption(
        "--update-goldens", action="store_true", default=False,
        help="re-record unitrack episode golden files instead of comparing with them",
    )


class EpisodeRegression:
    """What the ``episode_regression`` fixture hands to a test."""

    def __init__(self, update: bool) -> None:
        self.update = update

    def check(self, env_id: str, *, agent: str, sequence: str, golden: Any,
              **kwargs: Any) -> EpisodeRecord:
        """Replay and compare (see :func:`unitrack_env.evaluation.regression.check_episode`)."""
        return check_episode(env_id, agent, sequence, golden, update=self.update, **kwargs)


@pytest.fixture
def episode_regression(request: pytest.FixtureRequest) -> EpisodeRegression:
    """Replay an agent on a recorded episode and fail on metric drift."""
    return EpisodeRegression(bool(request.config.getoption("--update-goldens")))
