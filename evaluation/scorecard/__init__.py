"""The scorecard (``unitrack scorecard``): the paper's Table 2 and radar chart.

Every task's UniTrack head played with each appearance model, and each task's baseline:

* :mod:`.card` - :func:`~.card.scorecard`: play, store and score every cell, write the outputs;
* :mod:`.plan` - its tasks, heads, models (:class:`~.plan.ModelSpec`), data and cells;
* :mod:`.eta` and :mod:`.flops` - what a cell costs, the order cells run in, the ETA;
* :mod:`.table` and :mod:`.radar` - the Markdown / CSV table and the radar chart;
* :mod:`.intervals` - each cell's value with its 95% interval (``--ci``);
* :mod:`.correlation_study` - the paper's correlation study of a card's rows against other
  evaluations of the same models (statistics in :mod:`.correlation`, figure in
  :mod:`.correlation_plot`).

Exported here: :func:`scorecard` and :class:`ModelSpec` (its rows).
"""

from .card import scorecard
from .plan import ModelSpec

__all__ = ["ModelSpec", "scorecard"]
