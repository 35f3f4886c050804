"""``--method difix --checkpoint CKPT``: the DiFix3D-style baseline as an enhancer (thin adapter).

Each target is enhanced with one reference, RGB only — no geometry, no CFG.  Which reference
(``-o references=RULE``):

``nearest_pose`` (default, Difix3D's rule)
    per target, the reference camera minimising ``‖c_ref − c_target‖ + θ(R_ref, R_target)``: camera
    centre distance plus the geodesic angle (radians) between the two rotations, weights 1 : 1
    (nv-tlabs/Difix3D@c76edc59 ``examples/utils.py``, ``CameraPoseInterpolator.find_nearest_assignments``);
    ties go to the first reference.  Candidates are the packet's references (the protocol's best fit
    frames by Eq. 2), and distances are measured in the packet's normalised frame (largest pairwise
    camera distance 1), where Difix3D measures them in gsplat's normalised world: see
    docs/evaluation_profiles.md.
``eq2``
    the packet's first reference (the packet builder orders references best first by Eq. 2) for every
    target.

The (reference, target) pairs run as independent sets stacked on the batch axis (``sets_per_call``
bounds how many per UNet call).  A packet of any size is reflect-padded once to the network's size
multiple and the output cropped back (:mod:`setdiff_bench.enhancers.padding`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.enhancers.padding import crop, pad_packet
from setdiff_bench.enhancers.setdiff import ModelEnhancer, load_enhancer
from setdiff_bench.errors import UsageError
from setdiff_bench.types import Packet

REFERENCE_RULES = ("nearest_pose", "eq2")
DEFAULT_REFERENCE_RULE = "nearest_pose"


def rotation_angle(r_a: np.ndarray, r_b: np.ndarray) -> float:
    """Geodesic angle in radians between two rotation matrices: ``arccos((tr(R_aᵀ R_b) − 1) / 2)``.

    Equal to Difix3D's ``arccos(2 (q_a · q_b)² − 1)`` on unit quaternions.
    """
    cosine = (float(np.trace(np.asarray(r_a, np.float64).T @ np.asarray(r_b, np.float64))) - 1.0) / 2.0
    return float(np.arccos(np.clip(cosine, -1.0, 1.0)))


def pose_distance(
    a: Camera, b: Camera, translation_weight: float = 1.0, rotation_weight: float = 1.0
) -> float:
    """Difix3D's pose distance: weighted camera-centre distance plus weighted rotation angle (radians)."""
    return translation_weight * float(np.linalg.norm(a.center - b.center)) + rotation_weight * rotation_angle(
        a.R, b.R
    )


def nearest_pose_assignments(references: Sequence[Camera], targets: Sequence[Camera]) -> list[int]:
    """For each target, the index of the reference with the smallest :func:`pose_distance` (first on ties)."""
    if not references:
        raise UsageError("the difix nearest_pose rule needs at least one reference in the packet")
    return [int(np.argmin([pose_distance(ref, target) for ref in references])) for target in targets]


class DifixEnhancer(ModelEnhancer):
    """A DiFix checkpoint with a per-target reference rule (module docstring)."""

    def __init__(self, base: ModelEnhancer, references: str) -> None:
        super().__init__(
            base.name,
            base.model,
            base.config,
            base.checkpoint,
            guidance_scale=base.guidance_scale,
            sets_per_call=base.sets_per_call,
            max_references=1,
            targets_per_set=1,
        )
        self.references = references
        self.options = {**self.options, "references": references}

    def _repr_fields(self) -> dict[str, object]:
        return {**super()._repr_fields(), "references": self.references}

    def enhance(self, packet: Packet) -> torch.Tensor:
        """``(M, 3, H, W)`` float32 in [0, 1], packet order, any H × W; each target with its rule's one
        reference."""
        if self.references == "eq2" or len(packet.references) == 0:
            return super().enhance(packet)
        # pad once here: the parts below are then at the size multiple and go to the model as they are
        padded, padding = pad_packet(packet, self.size_multiple)
        choice = nearest_pose_assignments(padded.references.cameras, padded.targets.cameras)
        output = torch.empty((len(padded.targets), 3, padded.height, padded.width), dtype=torch.float32)
        for reference in sorted(set(choice)):
            ids = [i for i, r in enumerate(choice) if r == reference]
            part = dataclasses.replace(
                padded, references=padded.references.subset([reference]), targets=padded.targets.subset(ids)
            )
            output[ids] = super().enhance(part)
        return crop(output, padding)


def create(
    checkpoint: str | None = None,
    device: str | None = None,
    dtype: str | None = None,
    sets_per_call: int | None = None,
    references: str = DEFAULT_REFERENCE_RULE,
) -> DifixEnhancer:
    """Factory of ``--method difix`` (``-o references=nearest_pose|eq2``)."""
    if references not in REFERENCE_RULES:
        raise UsageError(
            f"references must be one of {', '.join(REFERENCE_RULES)}, got {references!r}", "-o references"
        )
    base = load_enhancer("difix", checkpoint, device=device, dtype=dtype, sets_per_call=sets_per_call)
    return DifixEnhancer(base, references)
