"""Issue 52's two arms side by side: a SetDiff trained and evaluated with fit C-maps, and its twin trained and
evaluated with true C-maps (``benchmarks/true_geometry_store.py``), gathered into one JSON.

Per arm (``--arm NAME=WORK``; WORK holds what these commands wrote):

* ``runs/sets-NAME`` and ``runs/render-NAME``: ``setdiff-bench run`` of the model and of ``identity`` on the arm's
  store (test split) — means per group and the paired gain per group and per scene (``reporting.paired``);
* ``runs/sets4-NAME`` (optional): the model run with ``-o targets_per_set=4``, the largest target count of its
  training sets (the default enhances a packet's 13 targets in one set);
* ``abl/ablation_setsize.md``: ``setdiff-bench ablate setsize --sizes 1+1,2+1,3+1`` on the arm's n3 test packets
  (and, from its ``abl/work/ablation_setsize/runs``, the PSNR steps between set sizes per scene);
* ``usage.json``: ``benchmarks/diagnose_set_usage.py --group n3 --other-scene --true-packets TWIN``.

    python benchmarks/sparse_set_arms.py --arm fit=WORK_FIT --arm true=WORK_TRUE --out sparse_set_arms
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.common import write_result

METRICS = ("psnr", "ssim", "lpips")


def group_means(run: Path) -> dict[str, dict[str, float]]:
    frame = pd.read_parquet(run / "metrics.parquet")
    return {
        str(group): {m: round(float(rows[m].mean()), 4) for m in METRICS}
        for group, rows in frame.groupby("group")
    }


#: A run's metrics rows are one target view each.
KEYS = ["packet_id", "view"]


def target_metrics(run: Path) -> pd.DataFrame:
    """A run's ``metrics.parquet``, indexed by target."""
    return pd.read_parquet(run / "metrics.parquet").set_index(KEYS)


def gain_summary(gain: pd.Series, scene: pd.Series) -> dict[str, Any]:
    """Per-target PSNR gains (dB): their mean and the mean per scene."""
    return {
        "psnr_gain": round(float(gain.mean()), 4),
        "psnr_gain_per_scene": {str(s): round(float(g.mean()), 4) for s, g in gain.groupby(scene)},
    }


def paired_by_scene(model: Path, render: Path) -> dict[str, dict[str, Any]]:
    """Per group: the mean PSNR gain over the render, and per scene (positive = the model better)."""
    a, b = target_metrics(model), target_metrics(render)
    joined = a[["group", "scene", "psnr"]].join(b[["psnr"]].rename(columns={"psnr": "psnr_render"}))
    gain = joined["psnr"] - joined["psnr_render"]
    return {
        str(group): gain_summary(gain[rows.index], rows["scene"]) for group, rows in joined.groupby("group")
    }


def setsize_steps(runs: Path, render: Path) -> dict[str, dict[str, Any]]:
    """The set-size ablation's PSNR steps on the n3 targets (``runs/<N+1>/metrics.parquet``, paired by target):
    2+1 − 1+1, 3+1 − 2+1, 3+1 − 1+1 and 3+1 − the render, each as the mean and per scene."""
    frames = {size: target_metrics(runs / size) for size in ("1+1", "2+1", "3+1")}
    psnr = pd.DataFrame({size: frame["psnr"] for size, frame in frames.items()})
    psnr["render"] = target_metrics(render)["psnr"].reindex(psnr.index)
    pairs = {
        "2+1 - 1+1": ("2+1", "1+1"),
        "3+1 - 2+1": ("3+1", "2+1"),
        "3+1 - 1+1": ("3+1", "1+1"),
        "3+1 - render": ("3+1", "render"),
    }
    return {name: gain_summary(psnr[a] - psnr[b], frames["3+1"]["scene"]) for name, (a, b) in pairs.items()}


def usage_summary(path: Path) -> dict[str, Any]:
    data = json.loads(path.read_text())
    rows = data["rows"]

    def mean(key: str) -> float | None:
        values = [r[key] for r in rows if key in r]
        return round(float(np.mean(values)), 4) if values else None

    layers: dict[str, dict[str, list[float]]] = {}
    for row in rows:
        for index, layer in enumerate(row["layers"]):
            name = f"layer{index}_{int(layer['tokens_per_view'])}tok"
            for key in ("reference_mass", "correspondence_lift", "correspondence_lift_true"):
                if key in layer:
                    layers.setdefault(name, {}).setdefault(key, []).append(layer[key])
    return {
        "packets": [r["packet"] for r in rows],
        "psnr_render": mean("psnr_render"),
        "psnr_full": mean("psnr_full"),
        "psnr_no_references": mean("psnr_no_references"),
        "psnr_other_scene_references": mean("psnr_other_scene_references"),
        "mean_abs_change_0+1": mean("mean_abs_change_0+1"),
        "mean_abs_change_other_scene_references": mean("mean_abs_change_other_scene_references"),
        "mean_abs_change_no_self_attention": mean("mean_abs_change_no_self_attention"),
        "mean_abs_change_no_unet": mean("mean_abs_change_no_unet"),
        "layers": {
            name: {key: round(float(np.mean(v)), 3) for key, v in values.items()}
            for name, values in layers.items()
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arm", action="append", required=True, help="NAME=WORK")
    parser.add_argument("--out", default="sparse_set_arms")
    parser.add_argument("--step", type=int, default=None, help="training step of the arms' checkpoints")
    args = parser.parse_args()
    payload: dict[str, Any] = {"benchmark": "sparse_set_arms", "arms": {}}
    if args.step is not None:
        payload["training_step"] = args.step
    for item in args.arm:
        name, _, work = item.partition("=")
        root = Path(work)
        model, render = root / "runs" / f"sets-{name}", root / "runs" / f"render-{name}"
        arm: dict[str, Any] = {
            "setdiff": group_means(model),
            "render": group_means(render),
            "gain_over_render": paired_by_scene(model, render),
        }
        sets_of_4 = root / "runs" / f"sets4-{name}"
        if (sets_of_4 / "metrics.parquet").is_file():
            arm["setdiff_targets_per_set_4"] = group_means(sets_of_4)
            arm["gain_over_render_targets_per_set_4"] = paired_by_scene(sets_of_4, render)
        table = root / "abl" / "ablation_setsize.md"
        if table.is_file():
            arm["setsize_table"] = [
                line
                for line in table.read_text().splitlines()
                if line.startswith(("| ", "- PSNR", "- SSIM", "- LPIPS"))
            ]
        ablation_runs = root / "abl" / "work" / "ablation_setsize" / "runs"
        if (ablation_runs / "3+1" / "metrics.parquet").is_file():
            arm["setsize_steps_n3"] = setsize_steps(ablation_runs, render)
        usage = root / "usage.json"
        if usage.is_file():
            arm["set_usage_n3"] = usage_summary(usage)
        payload["arms"][name] = arm
    print(json.dumps(payload, indent=1))
    print(f"wrote {write_result(args.out, payload)}")


if __name__ == "__main__":
    main()
