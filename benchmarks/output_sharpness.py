"""Does an enhancer sharpen or smooth?  Mean absolute Laplacian of its outputs against the ground truth.

PSNR rewards a smooth output where the detail is uncertain; LPIPS penalises it.  When two models trade
one for the other (issue 15's geometry-biased set attention gains PSNR and loses LPIPS), this says which
way each moved: per group, the mean over targets of ``mean |∇² gray|`` (OpenCV's 3×3 Laplacian of the
luma, images in [0, 1]) for the ground truth, the render and each run's saved outputs, and each run's
*restored share* ``(run − render) / (ground truth − render)`` — 0 keeps the render's sharpness, 1
reaches the ground truth's, above 1 over-sharpens.

Written by hand because no library scores a run folder this way; the Laplacian itself is OpenCV's, and
the images are read by the toolkit's own reader (``setdiff_bench.io.images.read_rgb``).

    python benchmarks/output_sharpness.py --packets runs/more/packets \\
        --run shipped=<run folder> --run biased=<run folder> [--out benchmarks/results/....json]

A run folder is what ``setdiff-bench run --out`` wrote (``metrics.parquet`` and ``images/``); every run
must score the same targets of the same store.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pandas as pd
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import machine
from setdiff_bench.errors import SetDiffBenchError, UsageError
from setdiff_bench.io.atomic import write_text_atomic
from setdiff_bench.io.images import read_rgb
from setdiff_bench.packets.store import PacketStore


def laplacian_energy(image: np.ndarray) -> float:
    """``mean |∇² luma|`` of an ``(H, W, 3)`` float32 RGB image in [0, 1] (OpenCV 3×3 Laplacian)."""
    gray = cv2.cvtColor(np.ascontiguousarray(image, dtype=np.float32), cv2.COLOR_RGB2GRAY)
    return float(np.abs(cv2.Laplacian(gray, cv2.CV_32F)).mean())


def measure(store: PacketStore, runs: dict[str, Path]) -> list[dict[str, Any]]:
    """One record per target of the first run: group, packet, view and the Laplacian energy of the ground
    truth, the render and every run's output."""
    tables = {name: pd.read_parquet(folder / "metrics.parquet") for name, folder in runs.items()}
    first = next(iter(tables.values()))
    indexed = {name: table.set_index(["packet_id", "view"]) for name, table in tables.items()}
    records = []
    for packet_id, rows in tqdm(first.groupby("packet_id", sort=True), desc="packets", unit="packet"):
        truth, _ = store.load_ground_truth(packet_id)
        renders = store.load_packet(packet_id).targets.images.float()
        for view in sorted(int(v) for v in rows["view"]):
            record: dict[str, Any] = {
                "packet_id": packet_id,
                "group": str(rows["group"].iloc[0]),
                "view": view,
                "ground_truth": laplacian_energy(truth[view].permute(1, 2, 0).numpy()),
                "render": laplacian_energy(renders[view].permute(1, 2, 0).numpy()),
            }
            for name, table in indexed.items():
                if (packet_id, view) not in table.index:
                    raise UsageError(f"no output for {packet_id} view {view}", runs[name])
                record[name] = laplacian_energy(read_rgb(runs[name] / table.loc[(packet_id, view), "image"]))
            records.append(record)
    return records


def summary(records: list[dict[str, Any]], names: list[str]) -> dict[str, float]:
    """Means over targets, and each run's restored share of the render → ground-truth gap."""
    result = {key: statistics.fmean(r[key] for r in records) for key in ("ground_truth", "render", *names)}
    gap = result["ground_truth"] - result["render"]
    for name in names:
        result[f"{name}_restored"] = (result[name] - result["render"]) / gap if gap else float("nan")
    result["targets"] = len(records)
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--packets", required=True, type=Path, help="the packet store the runs scored")
    parser.add_argument("--run", action="append", required=True, help="NAME=RUN_FOLDER (repeatable)")
    parser.add_argument("--out", type=Path, help="JSON output (default: print only)")
    args = parser.parse_args()
    runs: dict[str, Path] = {}
    for spec in args.run:
        name, sep, folder = spec.partition("=")
        if not sep or not name or not folder:
            parser.error(f"--run expects NAME=RUN_FOLDER, got {spec!r}")
        runs[name] = Path(folder)
    try:
        records = measure(PacketStore(args.packets), runs)
    except (SetDiffBenchError, OSError) as error:  # a missing run folder, image or packet: one line, exit 2
        print(f"output_sharpness: error: {error}", file=sys.stderr)
        return 2
    names = list(runs)
    groups = sorted({r["group"] for r in records})
    result = {
        "benchmark": "output_sharpness",
        "command": " ".join(["python", *sys.argv]),
        "machine": machine(),
        "all": summary(records, names),
        "groups": {g: summary([r for r in records if r["group"] == g], names) for g in groups},
        "targets": records,
    }
    print(json.dumps({"all": result["all"], "groups": result["groups"]}, indent=2))
    if args.out:
        write_text_atomic(args.out, json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
