"""``--method difix --checkpoint CKPT``: the DiFix3D-style baseline as an enhancer (thin adapter).

Each target is enhanced with the packet's first reference (the packet builder orders references
best first by Eq. 2), RGB only — no geometry, no CFG.  The M (reference, target) pairs run as M
independent sets stacked on the batch axis (``sets_per_call`` bounds how many per UNet call).
"""

from __future__ import annotations

from setdiff_bench.enhancers.setdiff import ModelEnhancer, load_enhancer


def create(checkpoint: str | None = None, device: str | None = None, dtype: str | None = None,
           sets_per_call: int | None = None) -> ModelEnhancer:
    """Factory of ``--method difix``."""
    return load_enhancer("difix", checkpoint, device=device, dtype=dtype, sets_per_call=sets_per_call)
