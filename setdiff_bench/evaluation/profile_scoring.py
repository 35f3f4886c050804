"""Score a finished run under an evaluation profile (:mod:`setdiff_bench.protocols.profiles`).

Output, next to the run's own tables (``<run>/profiles/<profile>/``)::

    metrics.parquet   one row per scored target (the run's key columns, ``profile``, the profile's metrics)
    scenes.parquet    per (method, group, scene) means and image counts
    groups.parquet    per (method, group) values under the profile's averaging, with scene and image counts
    profile.json      the profile, the run, the data root, coverage notes
    euvs_compat.txt   (EUVS profiles) frames where EUVS's positional mask pairing differs from ours

Size rules.  ``working`` profiles rescore the store's ground truth.  The others read the original
capture and mask from the dataset (``data``): the ground truth is brought to the profile's size with
PIL bicubic (what 3DGS's ``PILtoTorch`` does), the mask with nearest; the run's prediction (made at
the working resolution over the protocol's crop window) is resized with PIL bicubic onto that window
at the profile's size.  This upsampling is the one difference no profile can remove: a method that
renders directly at 1600×900 has detail a 576×1024 enhancer never produced (docs/evaluation_profiles.md).
A target seen in several packets is scored once (its first packet). Profiles with ``scenes = "split"``
score the test-split rows only; ``"all"`` profiles score every row (run with ``--split all``).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch

from setdiff_bench.errors import UsageError
from setdiff_bench.evaluation.euvs_compat import compat_report
from setdiff_bench.io.atomic import atomic_path, write_text_atomic
from setdiff_bench.io.images import read_mask, read_rgb
from setdiff_bench.io.jsonable import jsonable
from setdiff_bench.io.run_layout import (
    EUVS_COMPAT_FILE,
    GROUPS_FILE,
    KEY_COLUMNS,
    METRICS_FILE,
    PROFILE_FILE,
    PROFILES_DIR,
    SCENES_FILE,
    TARGET_COLUMNS,
)
from setdiff_bench.loaders import load_scenes
from setdiff_bench.metrics.dinov2 import final_score, masked_cosine
from setdiff_bench.metrics.registry import METRICS
from setdiff_bench.packets.store import PacketStore
from setdiff_bench.packets.working_view import crop_window
from setdiff_bench.protocols import load_protocol
from setdiff_bench.protocols.profiles import (
    PROFILE_COLUMN,
    EvaluationProfile,
    aggregate,
    centre_crop_box,
    nearest_resize_mask,
    pil_resize,
    render_size,
)


@dataclass(frozen=True)
class ScoredPair:
    """One target at the profile's size: ``(H, W, 3)`` uint8 prediction and ground truth, ``(H, W)`` bool mask."""

    prediction: np.ndarray
    ground_truth: np.ndarray
    mask: np.ndarray


def to_uint8(image: np.ndarray) -> np.ndarray:
    """``(H, W, 3)`` float in [0, 1] → uint8 (round to nearest; exact for 8-bit sources)."""
    return np.round(np.clip(image, 0.0, 1.0) * 255.0).astype(np.uint8)


def profile_pair(
    profile: EvaluationProfile,
    prediction: np.ndarray,
    original: np.ndarray,
    original_mask: np.ndarray,
    window: tuple[int, int, int, int],
) -> ScoredPair:
    """Bring one target to the profile's size.

    Args:
        profile: a profile with ``size`` ``"render_capped"`` or ``"native"``.
        prediction: ``(h, w, 3)`` uint8 output at the working resolution.
        original: ``(H, W, 3)`` uint8 capture as stored in the dataset.
        original_mask: ``(H, W)`` bool, True = evaluate.
        window: ``(left, top, width, height)`` of the protocol's crop in original pixels (the region the
            prediction covers).

    Returns:
        The scored prediction, ground truth and mask (cropped to the window scaled to the profile's
        size, then to the profile's centre crop).
    """
    height, width = original.shape[:2]
    if profile.size == "render_capped":
        size = render_size(width, height, profile.max_width or width)
    else:
        size = (width, height)
    ground_truth = pil_resize(original, size)
    mask = (
        nearest_resize_mask(original_mask, size)
        if original_mask.shape != (size[1], size[0])
        else original_mask
    )
    sx, sy = size[0] / width, size[1] / height
    left, top, crop_w, crop_h = window
    box = (round(left * sx), round(top * sy), round((left + crop_w) * sx), round((top + crop_h) * sy))
    ground_truth = ground_truth[box[1] : box[3], box[0] : box[2]]
    mask = mask[box[1] : box[3], box[0] : box[2]]
    prediction = pil_resize(prediction, (box[2] - box[0], box[3] - box[1]))
    if profile.crop is not None:
        c_left, c_top, c_right, c_bottom = centre_crop_box(
            ground_truth.shape[1], ground_truth.shape[0], profile.crop[1], profile.crop[0]
        )
        ground_truth = ground_truth[c_top:c_bottom, c_left:c_right]
        prediction = prediction[c_top:c_bottom, c_left:c_right]
        mask = mask[c_top:c_bottom, c_left:c_right]
    return ScoredPair(
        np.ascontiguousarray(prediction), np.ascontiguousarray(ground_truth), np.ascontiguousarray(mask)
    )


def image_metrics(profile: EvaluationProfile, pair: ScoredPair, device: str = "cpu") -> dict[str, float]:
    """The profile's image metrics of one pair."""

    def tensor(image: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(image.astype(np.float32) / 255.0).permute(2, 0, 1)[None].to(device)

    pred, target = tensor(pair.prediction), tensor(pair.ground_truth)
    mask = torch.from_numpy(pair.mask)[None, None].to(device)
    with torch.no_grad():
        return {name: float(METRICS[name].compute(pred, target, mask)[0]) for name in profile.metrics}


def score_run(
    run: str | Path,
    profile: EvaluationProfile,
    *,
    packets: str | Path | None = None,
    data: str | Path | None = None,
    dinov2: Any = None,
    device: str = "cpu",
    progress: bool | None = None,
) -> Path:
    """Score the finished run in ``run`` under ``profile``; returns the output folder (module docstring).

    Args:
        run: a run folder (``metrics.parquet``, ``images/``).
        profile: the evaluation profile.
        packets: the packet store the run was made on (needed by ``working`` profiles).
        data: the dataset root (needed by other profiles: original images and masks).
        dinov2: a loaded DINOv2 model (:func:`setdiff_bench.metrics.dinov2.load_dinov2`) for profiles with
            ``dinov2``; ``None`` skips the cosine and ``Final_Score``.
        device: where metrics run.

    Raises:
        UsageError: the run is unfinished, or the profile needs ``packets``/``data`` that were not given.
    """
    from tqdm import tqdm

    run = Path(run)
    metrics_path = run / METRICS_FILE
    if not metrics_path.is_file():
        raise UsageError("not a finished run (no metrics.parquet)", run)
    rows = pd.read_parquet(metrics_path).drop_duplicates(["method", *TARGET_COLUMNS], keep="first")
    if (
        profile.scenes == "split"
    ):  # the protocol's test scenes only (a --split all run holds train scenes too)
        rows = rows[rows["split"] == "test"]
        if not len(rows):
            raise UsageError(f"profile {profile.name} scores the test scenes; this run has none", run)
    if packets is None:
        raise UsageError(
            "scoring under a profile needs the packet store the run was made on (--packets)", run
        )
    store = PacketStore(packets)
    rows, without = _with_ground_truth(rows, store)
    if not len(rows):
        raise UsageError(
            f"profile {profile.name}: every target of this run is a novel-trajectory view without ground "
            "truth; no profile metric applies (FID / KID score them: --inception FILE)",
            run,
        )
    if profile.needs_dataset and data is None:
        raise UsageError(f"profile {profile.name} scores the original images: pass the dataset root (--data)")
    originals = _Originals(data) if profile.needs_dataset else None
    records = []
    for row in tqdm(
        rows.to_dict("records"),
        desc=f"profile {profile.name}",
        unit="image",
        disable=None if progress is None else not progress,
    ):
        prediction = to_uint8(read_rgb(run / row["image"]))
        if originals is None:
            gt, mask = store.load_ground_truth(row["packet_id"], targets=[int(row["view"])])
            pair = ScoredPair(prediction, to_uint8(gt[0].permute(1, 2, 0).numpy()), mask[0, 0].numpy())
        else:
            original, original_mask, window = originals.target(row)
            pair = profile_pair(profile, prediction, original, original_mask, window)
        record = {key: row.get(key) for key in KEY_COLUMNS}
        record[PROFILE_COLUMN] = profile.name
        record.update(image_metrics(profile, pair, device))
        if profile.dinov2 and dinov2 is not None:
            record["cos_dinov2"] = masked_cosine(dinov2, pair.prediction, pair.ground_truth, pair.mask)
            # linear in the four metrics, so its mean over images equals the score of the means
            record["final_score"] = final_score(
                record["ssim_euvs"], record["psnr_euvs"], record["lpips_euvs"], record["cos_dinov2"]
            )
        records.append(record)
    frame = pd.DataFrame.from_records(records)
    extra = [name for name, spec in METRICS.items() if spec.scope == "profile" and name in frame.columns]
    groups, scenes = aggregate(frame, [*profile.metrics, *extra], profile.aggregation)
    out = run / PROFILES_DIR / profile.name
    out.mkdir(parents=True, exist_ok=True)
    for name, table in ((METRICS_FILE, frame), (SCENES_FILE, scenes), (GROUPS_FILE, groups)):
        with atomic_path(out / name) as tmp:
            table.to_parquet(tmp, index=False)
    notes = _coverage_notes(profile, rows, store)
    if without:
        notes.append(
            f"{without} target(s) without ground truth (novel-trajectory views) left out: no profile metric "
            "applies to them"
        )
    info = {
        "profile": jsonable(asdict(profile)),
        "run": str(run.resolve()),
        "packets": str(Path(packets).resolve()),
        "data": str(Path(data).resolve()) if data else None,
        "dinov2": dinov2 is not None,
        "images": len(frame),
        "notes": notes,
    }
    write_text_atomic(out / PROFILE_FILE, json.dumps(info, indent=2, sort_keys=True) + "\n")
    if profile.name.startswith("euvs"):
        by_scene: dict[str, list[str]] = {}
        for row in rows.itertuples():
            by_scene.setdefault(str(row.scene), []).append(str(row.frame))
        write_text_atomic(out / EUVS_COMPAT_FILE, compat_report(by_scene))
    return out


def _with_ground_truth(rows: pd.DataFrame, store: Any) -> tuple[pd.DataFrame, int]:
    """The run's metric rows whose target has ground truth (:meth:`PacketStore.has_ground_truth`, by the
    row's ``packet_id`` and target ``view``), and how many were left out (novel-trajectory views)."""
    flags: dict[str, np.ndarray] = {}
    keep = []
    for packet_id, view in zip(rows["packet_id"], rows["view"], strict=True):
        if packet_id not in flags:
            flags[packet_id] = store.has_ground_truth(packet_id)
        keep.append(bool(flags[packet_id][int(view)]))
    mask = np.array(keep, dtype=bool)
    return rows[mask], int((~mask).sum())


def _coverage_notes(profile: EvaluationProfile, rows: pd.DataFrame, store: Any) -> list[str]:
    """What keeps this table from being the official one (scene set)."""
    notes = []
    if profile.scenes == "all":
        stored = set(store.index["scene"])
        scored = set(rows["scene"])
        missing = sorted(stored - scored)
        if missing:
            notes.append(
                f"{profile.name} averages over every scene; {len(missing)} scene(s) of the store were "
                f"not in this run (run it with --split all): {', '.join(missing[:10])}"
            )
    return notes


class _Originals:
    """Original captures and masks of run targets, from the dataset in its official layout."""

    def __init__(self, data: str | Path) -> None:
        self.data = data
        self.scenes: dict[tuple[str, str], Any] = {}

    def target(self, row: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray, tuple[int, int, int, int]]:
        protocol = load_protocol(str(row["protocol"]))
        key = (str(row["protocol"]), str(row["scene"]))
        if key not in self.scenes:
            self.scenes[key] = load_scenes(
                str(row["dataset"]), self.data, [str(row["scene"])], **dict(protocol.loader_options)
            )[0]
        frame = self.scenes[key].frame(str(row["frame"]))
        original = to_uint8(read_rgb(frame.image_path))
        height, width = original.shape[:2]
        if protocol.images.masks == "dataset" and frame.mask_path is not None:
            mask = read_mask(frame.mask_path)
            if mask.shape != (height, width):
                mask = nearest_resize_mask(mask, (width, height))
        else:
            mask = np.ones((height, width), dtype=bool)
        resolution = protocol.images.resolution or (height, width)
        crop = crop_window(width, height, resolution, protocol.images.resize)
        return original, mask, (crop.left, crop.top, crop.width, crop.height)
