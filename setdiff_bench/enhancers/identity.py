"""``--method identity``: the raw 3DGS render, unchanged.

This is the paper's "3DGS" row (Tables 1, 2, 4) and "OmniRe" row (Table 3): every enhancer is
compared with the render it started from.
"""

from __future__ import annotations

import torch

from setdiff_bench.enhancers.base import enhancer_repr
from setdiff_bench.types import Packet


class IdentityEnhancer:
    """Returns the packet's target renders as they are."""

    name = "identity"

    def __init__(self) -> None:
        self.options: dict[str, object] = {}

    def __repr__(self) -> str:
        return enhancer_repr(self)

    def enhance(self, packet: Packet) -> torch.Tensor:
        """``(M, 3, H, W)`` float32: a copy of ``packet.targets.images``."""
        return packet.targets.images.detach().to(torch.float32).clone()


def create() -> IdentityEnhancer:
    """Factory of ``--method identity`` (takes no options)."""
    return IdentityEnhancer()
