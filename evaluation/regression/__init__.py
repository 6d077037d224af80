"""Episode regression tests for trackers: golden files of metrics and action digests.

Record once, then every test run replays the agent on the same episode and fails with a
readable diff when a metric moves beyond its tolerance::

    def test_my_tracker(episode_regression):
        episode_regression.check(
            "UniTrack/MOT16-v0", agent="my-tracker", sequence="SYN-01",
            golden="tests/goldens/my-tracker-syn01.json",
        )

Run ``pytest --update-goldens`` to (re)record. The fixture comes from the pytest plugin that
unitrack-env registers (``unitrack_env.evaluation.regression.plugin``).
"""

from unitrack_env.evaluation.regression.golden import (
    EpisodeRecord,
    GoldenMismatch,
    check_episode,
    compare_records,
    record_episode,
)

__all__ = ["EpisodeRecord", "GoldenMismatch", "check_episode", "compare_records", "record_episode"]
