"""What a track remembers of its appearance: the last observation, or a moving average.

More in docs/module-notes.md.
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
