"""Where EUVS's official scoring pairs a render with another frame's mask, and where its mask names differ.

We pair every target with its own mask by name.  The EUVS metric script
(ai4ce/EUVS-Benchmark@f3b2d907 ``baselines/3DGS/metrics_with_dyn_masks.py``) pairs by position in two
lists sorted differently:

* renders (``<image name>.png``, e.g. ``trav_1_channel_1_img_2.jpg.png``) sorted by the integer made of
  every digit in the file name (``extract_number``; a name without digits sorts as −1; ties keep
  ``os.listdir`` order, which we take as name order);
* masks (``dynamic_masks/<name with ".jpg" replaced by ".png">``, kept when listed in the set file)
  sorted as path strings.

The i-th render is scored with the i-th mask.  On MARS-style names (traversal and image numbers of
different digit counts) the two orders differ, and so do the official numbers from name-paired ones.

Mask file names also differ between EUVS's own tools: the metric script replaces ``".jpg"`` with
``".png"`` anywhere in the name, the 3DGS loader keeps the part before the first dot
(``split('.')[0] + '.png'``) and the mask extractor writes ``stem + '.png'``.  They agree for
``name.jpg`` and disagree for ``.JPG``/``.jpeg`` and names with several dots.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import PurePosixPath


def digits_key(file_name: str) -> int:
    """EUVS ``extract_number``: the integer of every digit in ``file_name`` concatenated; −1 without digits."""
    digits = "".join(c for c in file_name if c.isdigit())
    return int(digits) if digits else -1


def metric_script_mask_name(image_name: str) -> str:
    """Mask name as the metric script derives it: ``".jpg"`` replaced by ``".png"`` everywhere."""
    return image_name.replace(".jpg", ".png")


def loader_mask_name(image_name: str) -> str:
    """Mask name as the EUVS 3DGS loader derives it: the part before the first dot + ``.png``."""
    return image_name.split(".")[0] + ".png"


def extractor_mask_name(image_name: str) -> str:
    """Mask name as the EUVS mask extractor writes it: the stem (last suffix removed) + ``.png``."""
    return PurePosixPath(image_name).stem + ".png"


@dataclass(frozen=True)
class Mispairing:
    """One render that EUVS's positional pairing scores with another mask.

    Attributes:
        frame: the image name (``test_set.txt`` entry).
        official_mask: the mask file the official script pairs it with (``None``: fewer masks than renders).
        own_mask: the frame's own mask file name.
    """

    frame: str
    official_mask: str | None
    own_mask: str


def positional_mispairings(frames: Sequence[str]) -> list[Mispairing]:
    """The frames whose official (positional) mask is not their own.

    Args:
        frames: image names of one scene's evaluated set (``test_set.txt`` entries, e.g. ``x_1.jpg``).

    Returns:
        One :class:`Mispairing` per frame paired with another mask, in render order.
    """
    # os.listdir order is unspecified; name order is what a sorted listing gives and is stable.
    renders = sorted(sorted(frames), key=lambda name: digits_key(name + ".png"))
    masks = sorted({metric_script_mask_name(name) for name in frames})
    out = []
    for position, frame in enumerate(renders):
        official = masks[position] if position < len(masks) else None
        own = metric_script_mask_name(frame)
        if official != own:
            out.append(Mispairing(frame, official, own))
    return out


def mask_name_disagreements(frames: Sequence[str]) -> list[tuple[str, str, str, str]]:
    """``(frame, metric script, loader, extractor)`` mask names for the frames where they are not all equal."""
    rows = []
    for frame in frames:
        names = (metric_script_mask_name(frame), loader_mask_name(frame), extractor_mask_name(frame))
        if len(set(names)) > 1:
            rows.append((frame, *names))
    return rows


def compat_report(scenes: dict[str, Sequence[str]]) -> str:
    """A plain-text report over ``{scene: evaluated frame names}``: positional mispairings and mask-name
    disagreements, one line per frame, and a per-scene count (empty scenes are listed as clean)."""
    lines = [
        "EUVS compatibility report: frames where the official script's numbers must differ from ours",
        "(we pair render and mask by name; metrics_with_dyn_masks.py pairs them by position)",
    ]
    total_mis = total_names = 0
    for scene in sorted(scenes):
        frames = list(scenes[scene])
        mis = positional_mispairings(frames)
        names = mask_name_disagreements(frames)
        total_mis += len(mis)
        total_names += len(names)
        lines.append(
            f"scene {scene}: {len(frames)} frames, {len(mis)} positional mispairings, "
            f"{len(names)} mask-name disagreements"
        )
        lines += [
            f"  mispaired: {m.frame} -> official mask {m.official_mask or '(none)'} (own: {m.own_mask})"
            for m in mis
        ]
        lines += [f"  mask name: {f}: metric script {a}, loader {b}, extractor {c}" for f, a, b, c in names]
    lines.append(f"total: {total_mis} positional mispairings, {total_names} mask-name disagreements")
    return "\n".join(lines) + "\n"
