"""What a track remembers of its appearance: the last observation, or a moving average.

The paper and the authors' code compare a track by its *last* matched observation
(``curr_feat``): one wrong match replaces its appearance by another object's, and the track
follows that object from then on (on the synthetic MOT16 set, most appearance-only errors).
JDE, whose association UniTrack's MOT head follows, keeps a moving average instead
(``smooth_feat``, momentum 0.9). :func:`remember` averages UniTrack's payloads, *sets* of
location features, location by location (a box's 10 x 4 grid has the same 40 locations in
every frame), L2-normalised before and after; payloads of different shapes (masks of
different sizes) cannot be averaged so, and the newest is kept, as in the paper.
"""

from __future__ import annotations

from typing import Any

import torch
import torch.nn.functional as F


def remember(memory: Any, observation: Any, momentum: float) -> Any:
    """The payload a track keeps after matching ``observation``.

    ``momentum`` 0 (paper), or payloads that are not two tensors of one shape, keep the
    observation; else ``normalize(m * normalize(memory) + (1 - m) * normalize(observation))``
    per location.

    Example:
        >>> import torch
        >>> old, new = torch.tensor([[1.0, 0.0]]), torch.tensor([[0.0, 1.0]])
        >>> [round(v, 3) for v in remember(old, new, 0.75)[0].tolist()]
        [0.949, 0.316]
    """
    if momentum <= 0:
        return observation
    if not (isinstance(memory, torch.Tensor) and isinstance(observation, torch.Tensor)) \
            or memory.shape != observation.shape:
        return observation
    old = F.normalize(memory.float(), dim=-1)
    new = F.normalize(observation.float(), dim=-1)
    return F.normalize(momentum * old + (1.0 - momentum) * new, dim=-1).to(observation.dtype)
