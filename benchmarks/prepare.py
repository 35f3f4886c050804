"""Prepare benchmark: packet views per second on the synthetic default preset, and where the time goes.

Generates (or reuses) synthetic scenes of the ``default`` preset with ``setdiff-bench synth``, runs
``prepare synthetic`` on them with their in-scene fits, and reports views written per second and the
share of packet time spent rendering (render + C-map normalisation), reading captures and writing files
(PNG/EXR encode + SHA-256 + fragment index).  A second, no-op run times the resume check (re-hashing
every file).  The peer is the obvious alternative write path: every file written through
``setdiff_bench.io.images``' per-file atomic write (temporary file + fsync + rename) instead of one
folder rename per packet; it is timed on the same packet contents.  EXR sizes are also reported for
float32 (stored) versus half, the precision trade-off named in ``setdiff_bench.packets.store``.

    python benchmarks/prepare.py [--data DIR] [--scenes 1] [--workers 1] [--peer-packets 5]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.common import machine, write_result
from setdiff_bench.io.images import to_numpy_hwc, write_exr, write_png
from setdiff_bench.packets.prepare import prepare
from setdiff_bench.packets.store import PacketStore
from setdiff_bench.packets.writer import CMAP_CHANNELS, EXR_ATTRIBUTES


def ensure_scenes(data: Path, scenes: int) -> None:
    """Generate ``scenes`` default-preset scenes (with fits) into ``data`` unless they are there."""
    present = [p for p in data.glob("*/scene.json")] if data.is_dir() else []
    if len(present) >= scenes and all((p.parent / "fits" / "lane0.ply").is_file() for p in present):
        return
    command = [
        sys.executable,
        "-m",
        "setdiff_bench",
        "synth",
        "--preset",
        "default",
        "--scenes",
        str(scenes),
        "--out",
        str(data),
        "--device",
        "cpu",
        "--no-progress",
    ]
    print("generating:", " ".join(command), flush=True)
    subprocess.run(command, check=True)


def packet_views(store: PacketStore, packet_id: str) -> list[tuple[str, np.ndarray, np.ndarray | None]]:
    """(file stem, rgb or gt/mask image, cmap+alpha) of every file of a packet, as arrays to rewrite."""
    packet = store.load_packet(packet_id)
    gt, masks = store.load_ground_truth(packet_id)
    files: list[tuple[str, np.ndarray, np.ndarray | None]] = []
    for role, views in (("ref", packet.references), ("tgt", packet.targets)):
        for i in range(len(views)):
            cmap = np.concatenate([to_numpy_hwc(views.cmaps[i]), to_numpy_hwc(views.alphas[i])], axis=2)
            files.append((f"{role}_{i:02d}", to_numpy_hwc(views.images[i]), cmap))
    for i in range(len(gt)):
        files.append((f"tgt_{i:02d}_gt", to_numpy_hwc(gt[i]), None))
        files.append((f"tgt_{i:02d}_mask", masks[i, 0].numpy(), None))
    return files


def time_writes(files, folder: Path, atomic: bool) -> float:
    start = time.perf_counter()
    for stem, image, cmap in files:
        write_png(folder / f"{stem}.png", image, atomic=atomic)
        if cmap is not None:
            write_exr(
                folder / f"{stem}_cmap.exr", cmap, CMAP_CHANNELS, attributes=EXR_ATTRIBUTES, atomic=atomic
            )
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--data",
        type=Path,
        default=Path(tempfile.gettempdir()) / "setdiff-bench" / "synthetic-default",
        help="synthetic default-preset scenes (generated here when missing)",
    )
    parser.add_argument("--scenes", type=int, default=1, help="scenes to generate/use (the preset has 5)")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument(
        "--peer-packets", type=int, default=5, help="packets rewritten for the write-path peer"
    )
    args = parser.parse_args()
    ensure_scenes(args.data, args.scenes)
    names = sorted(p.parent.name for p in args.data.glob("*/scene.json"))[: args.scenes]
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory(prefix="setdiff-prepare-bench-") as tmp:
        out = Path(tmp) / "store"
        summary = prepare(
            "synthetic", args.data, out, fits=args.data, scenes=names, workers=args.workers, progress=False
        )
        rerun = prepare(
            "synthetic", args.data, out, fits=args.data, scenes=names, workers=args.workers, progress=False
        )
        store = PacketStore(out)
        busy = summary.render_s + summary.read_s + summary.write_s
        files = [f for pid in store.packet_ids()[: args.peer_packets] for f in packet_views(store, pid)]
        (Path(tmp) / "plain").mkdir(exist_ok=True)
        ours = time_writes(files, Path(tmp) / "plain", atomic=False)
        (Path(tmp) / "atomic").mkdir(exist_ok=True)
        peer = time_writes(files, Path(tmp) / "atomic", atomic=True)
        cmaps = [c for _, _, c in files if c is not None]
        write_exr(Path(tmp) / "f32.exr", cmaps[0], CMAP_CHANNELS, attributes=EXR_ATTRIBUTES)
        write_exr(Path(tmp) / "f16.exr", cmaps[0], CMAP_CHANNELS, half=True, attributes=EXR_ATTRIBUTES)
        exr_f32, exr_f16 = (Path(tmp) / "f32.exr").stat().st_size, (Path(tmp) / "f16.exr").stat().st_size
        height, width = cmaps[0].shape[:2]
    results = {
        "scenes": names,
        "packets": summary.written,
        "views": summary.views_written,
        "resolution": [height, width],
        "wall_s": summary.wall_s,
        "views_per_s": summary.views_written / summary.wall_s,
        "packet_time_s": {
            "render_and_normalise": summary.render_s,
            "read_captures": summary.read_s,
            "write_files": summary.write_s,
        },
        "share": {
            "render": summary.render_s / busy,
            "read": summary.read_s / busy,
            "write": summary.write_s / busy,
        },
        "planning_and_merge_s": summary.wall_s - busy,
        "resume_noop_run_s": rerun.wall_s,
        "resume_skipped": rerun.skipped,
        "write_path_peer": {
            "files": len(files) + len(cmaps),
            "folder_rename_no_fsync_s": ours,
            "per_file_atomic_fsync_s": peer,
            "ratio_peer_over_ours": peer / ours if ours else None,
        },
        "exr_bytes": {"float32": exr_f32, "half": exr_f16},
    }
    payload = {
        "benchmark": "prepare",
        "preset": "default",
        "workers": args.workers,
        "machine": machine(),
        "results": results,
        "note": "timings on a 2-core machine shared with other jobs (see load_average_1min); the torch "
        "renderer runs one thread per process (prepare's default)",
    }
    path = write_result("prepare", payload)
    share = results["share"]
    print(
        f"{'views':>8} {'views/s':>8} {'render':>7} {'read':>6} {'write':>6} {'resume s':>9} {'peer/ours':>9}"
    )
    print(
        f"{summary.views_written:8d} {results['views_per_s']:8.2f} {share['render']:7.1%} {share['read']:6.1%} "
        f"{share['write']:6.1%} {rerun.wall_s:9.2f} {results['write_path_peer']['ratio_peer_over_ours'] or 0:9.2f}"
    )
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
