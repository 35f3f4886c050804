"""Drive ``setdiff-bench serve`` from a recorded trajectory: a prepared packet store replayed tick by tick.

Each packet of the store is one tick: its references are a session's recorded frames (one session
per packet), its targets are the tick's rendered frames.  World-frame
cameras come from the store's index; C-maps are moved back from the packet's normalised frame to
the world frame (the inverse of ``prepare``'s normalisation).  Enhanced images are written as
``OUT/<packet_id>/<frame>.png``.

    setdiff-bench serve --checkpoint CKPT --port 50051 &
    python examples/drive_packets.py --packets STORE --out OUT [--address 127.0.0.1:50051] [--split test]

Against a server with TLS and a token, give the client side of the same options (the token from a file or
``$SETDIFF_SERVE_TOKEN``, never on the command line)::

    python examples/drive_packets.py --packets STORE --out OUT --address gpu-host:50051 \
        --tls-ca ca.pem --token-file token [--client-cert client.pem --client-key client.key]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import grpc
import numpy as np
import torch

from setdiff_bench.errors import SetDiffBenchError
from setdiff_bench.evaluation.stream import Views
from setdiff_bench.geometry import denormalize_cmaps
from setdiff_bench.io.images import write_png
from setdiff_bench.packets.index import INDEX_FILE
from setdiff_bench.packets.store import PacketStore, row_camera
from setdiff_bench.serve.client import EnhancerClient, add_client_arguments, client_from_arguments
from setdiff_bench.types import ViewSet


def world_views(view_set: ViewSet, rows: list, anchor_world, scale: float, source: str) -> Views:
    """A packet's views back in the world frame (:func:`~setdiff_bench.geometry.denormalize_cmaps`, ``R, t`` of the
    anchor)."""
    cameras = [row_camera(row, source, world=True) for row in rows]
    cmaps = denormalize_cmaps(
        view_set.cmaps, view_set.alphas, anchor_world.R, anchor_world.t, scale, dtype=torch.float32
    )
    images = torch.round(view_set.images * 255).to(torch.uint8)
    return Views(
        images=images, cameras=cameras, cmaps=cmaps, alphas=view_set.alphas, names=list(view_set.names)
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--packets", type=Path, required=True)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--split", default="test")
    add_client_arguments(parser)
    args = parser.parse_args()
    store = PacketStore(args.packets)
    source = str(args.packets / INDEX_FILE)
    try:
        client = client_from_arguments(args)
    except SetDiffBenchError as error:
        parser.exit(2, f"{parser.prog}: error: {error.one_line()}\n")
    with client:
        try:
            drive(client, store, source, args)
        except grpc.RpcError as error:  # refused (a bad token, a full server, ...): say so in one line
            parser.exit(1, f"{parser.prog}: error: {error.code().name}: {error.details()}\n")


def drive(client: EnhancerClient, store: PacketStore, source: str, args: argparse.Namespace) -> None:
    """Replay every packet of ``args.split`` as one session and one tick; write the enhanced frames."""
    client.wait_ready()
    for packet_id in store.packet_ids(args.split):
        packet = store.load_packet(packet_id)
        rows = store.rows(packet_id)
        refs = [row for _, row in rows[rows["role"] == "ref"].iterrows()]
        tgts = [row for _, row in rows[rows["role"] == "target"].iterrows()]
        anchor = row_camera(tgts[0], source, world=True)
        session = client.start_session(world_views(packet.references, refs, anchor, packet.scale, source))
        images = client.enhance(session, world_views(packet.targets, tgts, anchor, packet.scale, source))
        client.close_session(session)
        for name, image in zip(packet.targets.names, images):
            write_png(args.out / packet_id / Path(name).with_suffix(".png"), np.asarray(image))
        print(f"{packet_id}: {len(images)} frames")


if __name__ == "__main__":
    main()
