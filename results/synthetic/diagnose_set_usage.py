"""How much does a trained SetDiff use the other views of its set?  (Diagnosis behind diagnosis.md.)

Loads a checkpoint and the test packets of a store and measures, per packet, the mean absolute
change of the enhanced targets (``(M, 3, H, W)`` in [0, 1]) when

* the set shrinks to 0, 1 or 3 references and one target per set (the set-size ablation's knobs);
* every set-mixer self-attention output is zeroed (the UNet keeps its convolutions);
* the UNet's correction is dropped (the render's own latents are decoded),

and, per set-mixer layer, the share of attention mass a token puts on its own view (1/V = no
preference) and the attention's normalised entropy (1 = uniform over all V·L tokens).

Usage::

    python results/synthetic/diagnose_set_usage.py --packets results/synthetic/work/packets \
        --checkpoint results/synthetic/work/checkpoints/setdiff --group lane+2 --packets-max 2
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import torch

from setdiff_bench.models.setdiff import set_mixer
from setdiff_bench.models.setdiff.checkpoint import load_model
from setdiff_bench.models.setdiff.inference import enhance_packet
from setdiff_bench.packets import PacketStore

ProcessorCall = Callable[..., torch.Tensor]


@contextmanager
def patched_set_attention(wrapper: Callable[[ProcessorCall], ProcessorCall]) -> Iterator[None]:
    """Temporarily replace :class:`SetSelfAttnProcessor.__call__` by ``wrapper(original)``."""
    original = set_mixer.SetSelfAttnProcessor.__call__
    set_mixer.SetSelfAttnProcessor.__call__ = wrapper(original)
    try:
        yield
    finally:
        set_mixer.SetSelfAttnProcessor.__call__ = original


def zeroed(original: ProcessorCall) -> ProcessorCall:
    """A processor whose output is zero (diffusers passes ``num_views`` only to a named parameter)."""
    def call(self: Any, attn: Any, hidden_states: torch.Tensor, encoder_hidden_states: Any = None,
             attention_mask: Any = None, temb: Any = None, num_views: int | None = None, **kwargs: Any) -> torch.Tensor:
        return 0.0 * original(self, attn, hidden_states, num_views=num_views)
    return call


def attention_stats(record: list[tuple[float, float]]) -> Callable[[ProcessorCall], ProcessorCall]:
    """A processor that appends (mean mass on the query's own view, mean normalised entropy) per layer."""
    def wrap(original: ProcessorCall) -> ProcessorCall:
        def call(self: Any, attn: Any, hidden_states: torch.Tensor, encoder_hidden_states: Any = None,
                 attention_mask: Any = None, temb: Any = None, num_views: int | None = None,
                 **kwargs: Any) -> torch.Tensor:
            assert num_views is not None
            views, tokens = num_views, hidden_states.shape[1]
            sets, heads = hidden_states.shape[0] // views, attn.heads
            query, key = attn.to_q(hidden_states), attn.to_k(hidden_states)
            dim = query.shape[-1] // heads
            query = query.reshape(sets, views * tokens, heads, dim).transpose(1, 2)
            key = key.reshape(sets, views * tokens, heads, dim).transpose(1, 2)
            weights = torch.softmax(query @ key.transpose(-1, -2) / dim ** 0.5, dim=-1)
            view_of = torch.arange(views * tokens) // tokens
            own = (view_of[:, None] == view_of[None, :]).to(weights.dtype)
            entropy = -(weights * torch.log(weights.clamp_min(1e-30))).sum(-1).mean()
            record.append((float((weights * own).sum(-1).mean()), float(entropy / math.log(views * tokens))))
            return original(self, attn, hidden_states, num_views=num_views)
        return call
    return wrap


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--packets", required=True)
    parser.add_argument("--checkpoint", required=True)
    parser.add_argument("--group", default="lane+2")
    parser.add_argument("--packets-max", type=int, default=2)
    args = parser.parse_args()
    store = PacketStore(args.packets)
    model = load_model(args.checkpoint)[0].eval()
    ids = [pid for pid in store.packet_ids("test") if f"__{args.group}__" in pid][: args.packets_max]
    rows = []
    for packet_id in ids:
        packet = store.load_packet(packet_id)
        full = enhance_packet(model, packet)
        row: dict[str, Any] = {"packet": packet_id, "references": len(packet.references),
                               "targets": len(packet.targets)}
        for refs in (0, 1, 3):
            smaller = enhance_packet(model, packet, max_references=refs, targets_per_set=1)
            row[f"mean_abs_change_{refs}+1"] = float((smaller - full).abs().mean())
        with patched_set_attention(zeroed):
            row["mean_abs_change_no_self_attention"] = float((enhance_packet(model, packet) - full).abs().mean())
        original_to_x0 = model.to_x0
        model.to_x0 = lambda latents, prediction: latents  # type: ignore[method-assign]
        try:
            row["mean_abs_change_no_unet"] = float((enhance_packet(model, packet) - full).abs().mean())
        finally:
            model.to_x0 = original_to_x0  # type: ignore[method-assign]
        stats: list[tuple[float, float]] = []
        with patched_set_attention(attention_stats(stats)):
            enhance_packet(model, packet, guidance_scale=1.0)
        views = len(packet.references) + len(packet.targets)
        row["own_view_attention_mass_per_layer"] = [round(mass, 4) for mass, _ in stats]
        row["attention_normalised_entropy_per_layer"] = [round(entropy, 4) for _, entropy in stats]
        row["uniform_over_views"] = round(1.0 / views, 4)
        rows.append(row)
    print(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
