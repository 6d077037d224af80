"""pytest plugin: the ``episode_regression`` fixture and the ``--update-goldens`` flag.

Installed with unitrack-env (entry point ``pytest11``), so it loads in every pytest session
of the environment: it imports nothing but pytest until a test uses the fixture.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest

from unitrack_env.roots import DataRootNotFound


def pytest_addoption(parser: pytest.Parser) -> None:
    """Add ``--update-goldens``."""
    group = parser.getgroup("unitrack")
    group.addoption(
        "--update-goldens", action="store_true", default=False,
        help="re-record unitrack episode golden files instead of comparing with them",
    )


class EpisodeRegression:
    """What the ``episode_regression`` fixture hands to a test (``update``: re-record)."""

    def __init__(self, update: bool, base: Path) -> None:
        self.update = update
        self.base = base

    def golden_path(self, golden: str | os.PathLike) -> Path:
        """``golden`` resolved against the test file's folder when relative."""
        path = Path(golden)
        return path if path.is_absolute() else self.base / path

    def check(self, env_id: str, *, agent: str, sequence: str, golden: str | os.PathLike,
              **kwargs: Any) -> Any:
        """Replay and compare (see :func:`unitrack_env.evaluation.regression.check_episode`).

        Fails with the metric diff alone; skips (with the reason) when the episode's data
        root is missing, so a clone without the benchmark data passes.
        """
        __tracebackhide__ = True
        # lazy: start-up cost (this plugin loads in every pytest session: +40 ms for golden)
        from .golden import GoldenMismatch, check_episode

        try:
            return check_episode(env_id, agent, sequence, self.golden_path(golden),
                                 update=self.update, **kwargs)
        except DataRootNotFound as exc:
            skip, message = True, f"no data for {env_id}: {exc}"
        except GoldenMismatch as exc:
            skip, message = False, str(exc)
        # Outside the except blocks, so that the report shows the message once (no chained
        # "During handling of the above exception" copy).
        if skip:
            pytest.skip(message)
        pytest.fail(message, pytrace=False)


@pytest.fixture
def episode_regression(request: pytest.FixtureRequest) -> EpisodeRegression:
    """Replay an agent on a recorded episode and fail on metric drift."""
    return EpisodeRegression(bool(request.config.getoption("--update-goldens")),
                             Path(request.path).parent)
