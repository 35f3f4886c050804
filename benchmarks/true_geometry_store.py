"""A packet store's true-geometry twin: the same packets with every view's C-map and alpha rendered from the
synthetic scene's true world instead of its 3DGS fit (issue 52's "true-geometry arm", a diagnostic).

What a model trained and evaluated on the twin can do tells "the set mechanism cannot copy" apart from "the
fit's geometry is too poor to copy from" (docs/sparse_benchmark.md, "Geometry audit").  Images (references'
captures, targets' renders), ground truth, masks, cameras and the normalisation are the source store's,
byte for byte where they are files; only the ``*_cmap.exr`` files change.  The world is rebuilt from each
scene's ``scene.json`` (:func:`benchmarks.reproject_geometry.world_model`) and rendered at the views'
dataset-frame cameras, then moved into the packet's normalised frame exactly as ``prepare`` moves the fit's
C-maps (:func:`setdiff_bench.geometry.normalize_packet`, which depends on the cameras only).  A twin is never
a leaderboard row: its C-maps come from knowledge no method has.

    python benchmarks/true_geometry_store.py --packets STORE --scenes SCENES --out TWIN [--split train|test|all]

Resumes: packets already in ``TWIN`` are kept.  ``TWIN``'s ``index.parquet`` is merged at the end.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import torch
from tqdm import tqdm

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(ROOT))

from benchmarks.reproject_geometry import world_model  # noqa: E402
from setdiff_bench.gaussians.model import GaussianModel  # noqa: E402
from setdiff_bench.gaussians.render import render  # noqa: E402
from setdiff_bench.geometry import normalize_packet  # noqa: E402
from setdiff_bench.io.images import to_numpy_hwc  # noqa: E402
from setdiff_bench.packets.index import merge_index  # noqa: E402
from setdiff_bench.packets.store import PacketStore, row_camera, timestamp_or_none  # noqa: E402
from setdiff_bench.packets.writer import PacketHeader, ViewContent, packet_dir, write_packet  # noqa: E402
from setdiff_bench.types import PacketKey, key_fields  # noqa: E402

#: Appended to the fit key of every twin packet, so a twin is never mistaken for its source.
TRUE_GEOMETRY_SUFFIX = "+true-geometry"


def twin_packet(
    store: PacketStore, packet_id: str, scenes: Path, out: Path, cache: dict[str, GaussianModel]
) -> None:
    """Write ``packet_id`` of ``store`` into the store at ``out`` with the true world's C-maps and alphas."""
    rows = store.rows(packet_id).reset_index(drop=True)
    packet = store.load_packet(packet_id)
    world_cameras = [row_camera(row, world=True) for _, row in rows.iterrows()]
    references = len(packet.references.images)
    with torch.no_grad():
        world = render(
            world_model(scenes, packet.scene, cache), world_cameras, with_geometry=True, tile_size=8
        )
    alphas = world.alpha.float()
    normalised = normalize_packet(world_cameras, world.cmap.float(), references, alphas=alphas)
    first = rows.iloc[0]
    if not np.isclose(normalised.scale, float(first["scale"]), rtol=1e-9):
        raise RuntimeError(f"{packet_id}: normalisation scale {normalised.scale} != stored {first['scale']}")
    has_truth = store.has_ground_truth(packet_id)
    truth, masks = (
        store.load_ground_truth(packet_id, [int(i) for i in np.flatnonzero(has_truth)])
        if has_truth.any()
        else (None, None)
    )
    truth_position = {int(t): k for k, t in enumerate(np.flatnonzero(has_truth))}
    views = [*packet.references.images, *packet.targets.images]
    contents = []
    for i, (_, row) in enumerate(rows.iterrows()):
        target = i - references
        known = row["role"] == "target" and target in truth_position
        contents.append(
            ViewContent(
                frame=row["frame"],
                sensor=row["sensor"],
                traversal=row["traversal"],
                timestamp_us=timestamp_or_none(row["timestamp_us"]),
                camera=row_camera(row),
                camera_world=world_cameras[i],
                image=to_numpy_hwc(views[i]),
                cmap=to_numpy_hwc(normalised.cmaps[i]),
                alpha=alphas[i, 0].numpy(),
                gt=to_numpy_hwc(truth[truth_position[target]]) if known and truth is not None else None,
                mask=masks[truth_position[target], 0].numpy() if known and masks is not None else None,
                overlap_score=None if pd.isna(row["overlap_score"]) else float(row["overlap_score"]),
            )
        )
    header = PacketHeader(
        **key_fields(PacketKey.from_row(first)),
        fit_key=f"{first['fit_key']}{TRUE_GEOMETRY_SUFFIX}",
        scale=float(first["scale"]),
        recipe=str(first["recipe"]),
        cmap_half=False,  # float32 EXRs whatever the source's: the true C-maps at full precision
    )
    write_packet(out, header, contents[:references], contents[references:])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--packets", type=Path, required=True, help="the source packet store")
    parser.add_argument(
        "--scenes", type=Path, required=True, help="the synthetic scenes the store was made from"
    )
    parser.add_argument("--out", type=Path, required=True, help="the twin store (created; resumed)")
    parser.add_argument("--split", default="all", help="train, test or all (default all)")
    args = parser.parse_args()
    store = PacketStore(args.packets)
    ids = store.packet_ids(None if args.split == "all" else args.split)
    cache: dict[str, GaussianModel] = {}
    todo = [p for p in ids if not (packet_dir(args.out, p) / "index.parquet").is_file()]
    for packet_id in tqdm(todo, desc="true-geometry twin", unit="packet"):
        twin_packet(store, packet_id, args.scenes, args.out, cache)
    merge_index(args.out)
    print(f"{len(todo)} packet(s) written, {len(ids) - len(todo)} kept: {args.out}")


if __name__ == "__main__":
    main()
