"""What a track remembers of its appearance: the last observation, or a moving average.

The UniTrack paper and the authors' code compare a track by the payload of its *last*
matched observation (``curr_feat``). One wrong match then replaces the track's appearance by
another object's, and the track follows that object from then on (on the synthetic MOT16
set, tracks captured by a persistent false detection this way account for most of the
appearance-only errors). JDE (Wang et al., "Towards Real-Time Multi-Object Tracking", 2020),
whose association UniTrack's MOT head follows, keeps an exponential moving average of the
track's embedding instead (``smooth_feat``, momentum 0.9), so that one observation moves the
memory by a tenth.

:func:`remember` applies that average to UniTrack's payloads, which are *sets* of location
features: a box pooled into a 10 x 4 grid has the same 40 locations in every frame, so the
average is taken location by location, each location L2-normalised before and after.
Payloads of different shapes (masks of different sizes) cannot be averaged that way; the
newest one is kept, as in the paper.
"""

from __future__ import annotations

from typing import Any

import torch
import torch.nn.functional as F


def remember(memory: Any, observation: Any, momentum: float) -> Any:
    """The payload a track keeps after matching ``observation``.

    Args:
        memory: The track's payload so far.
        observation: The matched observation's payload.
        momentum: Weight of the memory; 0 keeps the observation (paper and code).

    Returns:
        ``observation`` when ``momentum`` is 0 or the payloads are not two tensors of one
        shape; else ``normalize(momentum * normalize(memory) + (1 - momentum) *
        normalize(observation))`` per location (last dimension), in the observation's dtype.

    Example:
        >>> import torch
        >>> old, new = torch.tensor([[1.0, 0.0]]), torch.tensor([[0.0, 1.0]])
        >>> remember(old, new, 0.0).tolist()
        [[0.0, 1.0]]
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
