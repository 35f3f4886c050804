"""What the two ablations vary: the geometry variants of Table 5 and the set sizes of Table 6.

:data:`GEOMETRY_VARIANTS` are the [model] overrides that make each row; :data:`SET_SIZES` are the
(N references, M targets) pairs; :func:`parse_variants` / :func:`parse_sizes` read ``--variants`` and
``--sizes``.  :data:`METRICS` are the image metrics every ablation table shows.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from setdiff_bench.errors import UsageError

METRICS = ("psnr", "ssim", "lpips")


@dataclass(frozen=True)
class GeometryVariant:
    """One row of Table 5: its key (folder names), label, and the [model] overrides that make it."""

    key: str
    label: str
    overrides: Mapping[str, object]


# The C-map attention bias (``attention_bias = "cmap_distance"``, beyond the paper) is C-map geometry too:
# the rows without C-maps switch it off, the rows with C-maps keep the config's setting.
GEOMETRY_VARIANTS: tuple[GeometryVariant, ...] = (
    GeometryVariant("none", "None", {"use_geometry": False, "attention_bias": "none"}),
    GeometryVariant("cmap", "Coordinate maps", {"use_geometry": True, "geometry_inputs": ["cmap"]}),
    GeometryVariant(
        "pose",
        "Camera poses",
        {"use_geometry": True, "geometry_inputs": ["plucker"], "attention_bias": "none"},
    ),
    GeometryVariant("both", "Both", {"use_geometry": True, "geometry_inputs": ["cmap", "plucker"]}),
)

SET_SIZES: tuple[tuple[int, int], ...] = ((1, 1), (2, 1), (3, 1), (3, 2), (3, 4), (3, 6))


def parse_variants(text: str | None) -> tuple[GeometryVariant, ...]:
    """``"none,both"`` → those variants of :data:`GEOMETRY_VARIANTS`, in the paper's row order; ``None``:
    all four."""
    if text is None:
        return GEOMETRY_VARIANTS
    known = {variant.key: variant for variant in GEOMETRY_VARIANTS}
    wanted = [part.strip() for part in text.split(",") if part.strip()]
    unknown = [key for key in wanted if key not in known]
    if unknown or not wanted:
        raise UsageError(
            f"geometry variant {unknown[0]!r} is unknown (choose from {', '.join(known)})"
            if unknown
            else f"no geometry variant given (choose from {', '.join(known)})",
            "--variants",
        )
    return tuple(variant for variant in GEOMETRY_VARIANTS if variant.key in wanted)


def parse_sizes(text: str) -> tuple[tuple[int, int], ...]:
    """``"1+1,3+6"`` → ``((1, 1), (3, 6))``."""
    sizes = []
    for part in text.split(","):
        refs, sep, targets = part.strip().partition("+")
        if not sep or not refs.isdigit() or not targets.isdigit() or int(targets) < 1:
            raise UsageError(
                f"set size {part.strip()!r} is not N+M (N >= 0 references, M >= 1 targets)", "--sizes"
            )
        sizes.append((int(refs), int(targets)))
    return tuple(sizes)


def size_label(size: tuple[int, int]) -> str:
    return f"{size[0]} + {size[1]}"
