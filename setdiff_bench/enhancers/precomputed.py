"""``--method precomputed --from DIR``: score images that any external code produced.

Layout of ``DIR``.  For a target frame called ``F`` (its name in the packet index, e.g. ``000123.jpg``
or ``CAM_FRONT/n015...jpg``) let ``S`` be ``F`` without its extension.  The image is looked up, most
specific first, at::

    DIR/<protocol>/<group>/<scene>/S.<ext>     exactly what `setdiff-bench run` writes under <run>/images/
    DIR/<group>/<scene>/S.<ext>
    DIR/<scene>/S.<ext>
    DIR/S.<ext>

(``<protocol>``, ``<group>``, ``<scene>`` as :func:`setdiff_bench.io.names.safe_component` spells them:
the names themselves unless they hold a path separator) with ``<ext>`` one of ``png``, ``jpg``, ``jpeg`` (case-insensitive on the suffix as written: ``.png``,
``.PNG``...).  The first level holding a file wins; two files for one frame at the same level (say
``S.png`` and ``S.jpg``) are an error.  Use the ``<group>`` levels when one frame is a target of several
groups (DL3DV's 3/6/9-view settings render the same frame from different fits).  ``DIR`` may also be
a run folder of ``setdiff-bench run``: its ``images/`` subfolder is used.

Images must have the target's size; 8-bit files are read as value/255.  Before anything is enhanced
the runner asks :meth:`PrecomputedEnhancer.check_targets` about every target, and a missing frame is
one error that lists them (the first 10 and the count).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from setdiff_bench.enhancers.base import enhancer_repr
from setdiff_bench.errors import ImageError, UsageError
from setdiff_bench.io.images import read_rgb
from setdiff_bench.io.names import frame_relative, safe_component
from setdiff_bench.io.run_layout import IMAGES_DIR, MANIFEST_FILE
from setdiff_bench.types import Packet, TargetRef, key_fields

EXTENSIONS = (".png", ".jpg", ".jpeg")
SHOW_MISSING = 10


def candidate_folders(root: Path, ref: TargetRef) -> list[Path]:
    """The folders searched for ``ref``, most specific first (names as in :func:`safe_component`)."""
    protocol, group, scene = (safe_component(x) for x in (ref.protocol, ref.group, ref.scene))
    return [root / protocol / group / scene, root / group / scene, root / scene, root]


class PrecomputedEnhancer:
    """Reads each target's enhanced image from a folder (see the module docstring for the layout).

    Attributes:
        root: the folder searched (``DIR`` or ``DIR/images`` for a run folder).
    """

    name = "precomputed"

    def __init__(self, source: str | Path) -> None:
        root = Path(source).expanduser()
        if not root.is_dir():
            raise UsageError("precomputed images folder not found", root, parameter="source")
        if (root / MANIFEST_FILE).is_file() and (root / IMAGES_DIR).is_dir():
            root = root / IMAGES_DIR
        self.root = root.resolve()
        self.options = {"from": str(self.root)}
        self._listings: dict[Path, dict[str, list[Path]]] = {}

    def __repr__(self) -> str:
        return enhancer_repr(self, source=str(self.root))

    def _files_at(self, folder: Path, stem: str) -> list[Path]:
        """Image files ``folder/stem.<ext>`` (directory listings are cached: one per folder)."""
        base = folder / stem
        parent = base.parent
        if parent not in self._listings:
            listing: dict[str, list[Path]] = {}
            if parent.is_dir():
                for path in sorted(parent.iterdir()):
                    if path.suffix.lower() in EXTENSIONS and path.is_file():
                        listing.setdefault(path.name[: -len(path.suffix)], []).append(path)
            self._listings[parent] = listing
        return self._listings[parent].get(base.name, [])

    def locate(self, ref: TargetRef) -> Path | None:
        """The image file for ``ref``, or ``None`` when there is none.

        Raises:
            UsageError: two candidate files at the same level (ambiguous).
        """
        stem = str(frame_relative(ref.frame))
        for folder in candidate_folders(self.root, ref):
            found = self._files_at(folder, stem)
            if len(found) > 1:
                names = ", ".join(p.name for p in found)
                raise UsageError(
                    f"frame {ref.frame!r} of scene {ref.scene!r} has several images ({names})", folder
                )
            if found:
                return found[0]
        return None

    def check_targets(self, targets: Sequence[TargetRef]) -> None:
        """Raise one :class:`UsageError` listing every target without an image."""
        missing = [ref for ref in targets if self.locate(ref) is None]
        if missing:
            shown = ", ".join(f"{r.scene}/{r.frame} ({r.group})" for r in missing[:SHOW_MISSING])
            more = f" and {len(missing) - SHOW_MISSING} more" if len(missing) > SHOW_MISSING else ""
            raise UsageError(
                f"{len(missing)} of {len(targets)} target frames have no precomputed image: {shown}{more}",
                self.root,
            )

    def enhance(self, packet: Packet) -> torch.Tensor:
        """``(M, 3, H, W)`` float32 in [0, 1] read from disk, packet order."""
        images = []
        for frame in packet.targets.names:
            ref = TargetRef(**key_fields(packet), frame=frame)
            path = self.locate(ref)
            if path is None:
                self.check_targets([ref])
            try:
                pixels = read_rgb(path, expected_size=(packet.height, packet.width))
            except ImageError as error:
                raise ImageError(
                    f"precomputed image for {packet.scene}/{frame}: {error.problem}", path
                ) from None
            images.append(torch.from_numpy(np.ascontiguousarray(pixels.transpose(2, 0, 1))))
        return torch.stack(images)


def create(source: str | None = None) -> PrecomputedEnhancer:
    """Factory of ``--method precomputed`` (``source`` is ``--from DIR``)."""
    if not source:
        raise UsageError("method 'precomputed' needs a folder of enhanced images", parameter="source")
    return PrecomputedEnhancer(source)
