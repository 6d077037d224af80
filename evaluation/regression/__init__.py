"""Episode regression tests for trackers: golden files of metrics and action digests.

Record once, then every test run replays the agent on the same episode and fails with a
readable diff when a metric moves beyond its tolerance::

    def test_my_tracker(episode_regression):
        episode_regression.check(
            "UniTrack/MOT16-v0", agent="my-tracker", sequence="SYN-01",
            golden="goldens/my-tracker-syn01.json",  # next to the test file
        )

Run ``pytest --update-goldens`` to (re)record. The fixture comes from the pytest plugin that
unitrack-env registers (``unitrack_env.evaluation.regression.plugin``).
"""

from typing import Any

__all__ = ["EpisodeRecord", "GoldenMismatch", "check_episode", "compare_records", "record_episode"]


def __getattr__(name: str) -> Any:
    # The pytest plugin (a submodule) loads in every pytest session of the environment.
    if name in __all__:
        # lazy: start-up cost (golden imports the episode player and agents, +40 ms a session)
        from . import golden

        return getattr(golden, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
