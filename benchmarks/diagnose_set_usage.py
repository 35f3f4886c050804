"""How much does a trained SetDiff use the other views of its set?  (Diagnosis behind diagnosis.md.)

Loads a checkpoint and the test packets of a store and measures, per packet, the mean absolute
change of the enhanced targets (``(M, 3, H, W)`` in [0, 1]) when

* the set shrinks to 0, 1 or 3 references and one target per set (the set-size ablation's knobs);
* every set-mixer self-attention output is zeroed (the UNet keeps its convolutions);
* the UNet's correction is dropped (the render's own latents are decoded),

and, as controls against ground truth (PSNR of the targets in dB, masked as the benchmark scores them):
the full packet, its references removed (N → 0), and its references replaced by those of the same-group
packet of another test scene (``--other-scene``: what a model that fetches by geometry must lose),

and, per set-mixer layer (one pass without guidance, the whole packet as one set):

* ``own_view``: the share of attention mass a token puts on its own view (1/V = no preference);
* ``entropy``: the attention's normalised entropy (1 = uniform over all V·L tokens);
* ``set_mixer_drift_from_init`` (once per model): how far each set-mixer projection moved from its
  initialisation (relative Frobenius change);
* ``content_logit_std``: the spread (std over keys, mean over queries and heads) of the content logits
  q·k/√d, before any geometry bias: below ~1 a softmax over thousands of tokens stays near uniform
  whatever the keys hold; ``query_key_weight_norm``: ‖W_q‖·‖W_k‖ (Frobenius), its scale;
* ``reference_mass``: the mass a target token puts on reference tokens, over the references' share of
  the tokens (1 = no preference for references);
* ``correspondence_lift``: the mass a target token puts on the reference tokens that see the same
  surface (token surface points, from the C-maps, closer than one token footprint), over those
  tokens' share of all tokens (1 = attention ignores geometry; the paper's mechanism needs ≫ 1);
  ``correspondence_lift_true``: the same with the surface points of ``--true-packets`` (the store's
  true-geometry twin, ``benchmarks/true_geometry_store.py``): lift on true correspondences.

The C-map bias is the model's own: absolute (``cmap_distance``) or relative to the query token's
footprint (``cmap_relative``, on ray-snapped points).  A ``knn`` layer's weights are its own restricted
softmax (own view, k nearest reference tokens, "no match" key; :func:`knn_weights`), so its ``reference_mass``
and lifts count only the k neighbours it may reach, and its rows leave out the "no match" share.

Usage (on the demo's packets and the shipped model)::

    python benchmarks/diagnose_set_usage.py --packets runs/demo/work/packets --checkpoint tiny_setdiff \
        --group lane+2 --packets-max 2 --out benchmarks/results/set_usage_tiny_setdiff_step2250_lane2.json

    python benchmarks/diagnose_set_usage.py --packets runs/sparse/packets --checkpoint CKPT --group n3 \
        --packets-max 4 --other-scene --true-packets runs/sparse/packets_true --out set_usage.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from setdiff_bench.metrics.psnr import psnr
from setdiff_bench.models.setdiff import set_mixer
from setdiff_bench.models.setdiff.checkpoint import load_model
from setdiff_bench.models.setdiff.inference import enhance_packet
from setdiff_bench.models.setdiff.inputs import surface_points
from setdiff_bench.models.setdiff.train import initial_model
from setdiff_bench.packets.store import PacketStore

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


ProcessorBody = Callable[[Any, Any, torch.Tensor, int | None, dict[str, Any]], torch.Tensor]


def processor_call(body: ProcessorBody) -> ProcessorCall:
    """A processor ``__call__`` with the parameters diffusers looks for (it passes ``num_views``,
    ``token_points`` and ``num_references`` only to named parameters) that calls ``body(self, attn,
    hidden_states, num_views, kwargs)``; ``kwargs`` holds ``token_points`` (the C-map distance bias) and
    ``num_references`` (``knn`` layers) when the model sends them."""

    def call(
        self: Any,
        attn: Any,
        hidden_states: torch.Tensor,
        encoder_hidden_states: Any = None,
        attention_mask: Any = None,
        temb: Any = None,
        num_views: int | None = None,
        token_points: torch.Tensor | None = None,
        num_references: int | None = None,
        **kwargs: Any,
    ) -> torch.Tensor:
        if token_points is not None:
            kwargs["token_points"] = token_points
        if num_references is not None:
            kwargs["num_references"] = num_references
        return body(self, attn, hidden_states, num_views, kwargs)

    return call


def zeroed(original: ProcessorCall) -> ProcessorCall:
    """A processor whose output is zero."""

    def body(
        self: Any, attn: Any, hidden_states: torch.Tensor, num_views: int | None, kwargs: dict[str, Any]
    ) -> torch.Tensor:
        return 0.0 * original(self, attn, hidden_states, num_views=num_views, **kwargs)

    return processor_call(body)


def token_points(points: torch.Tensor, tokens: int) -> tuple[torch.Tensor, torch.Tensor, float]:
    """Pixel surface points ``(V, 4, H, W)`` (xyz·valid, valid) → per-token points ``(V·L, 3)``, validity
    ``(V·L,)`` and the median distance between horizontally adjacent valid tokens (one footprint)."""
    height, width = points.shape[-2:]
    # the token grid: the divisor pair of ``tokens`` closest to the image's aspect ratio
    h = min(
        (d for d in range(1, tokens + 1) if tokens % d == 0),
        key=lambda d: abs(math.log((d / (tokens // d)) / (height / width))),
    )
    w = tokens // h
    pooled = F.adaptive_avg_pool2d(points, (h, w))
    coverage = pooled[:, 3:]
    xyz = pooled[:, :3] / coverage.clamp_min(1e-6)
    valid = coverage[:, 0] > 0.5
    step = (xyz[:, :, :, 1:] - xyz[:, :, :, :-1]).norm(dim=1)[valid[:, :, 1:] & valid[:, :, :-1]]
    footprint = float(step.median()) if step.numel() else float("nan")
    return xyz.flatten(2).transpose(1, 2).reshape(-1, 3), valid.reshape(-1), footprint


def correspondence(
    target_rows: torch.Tensor, is_ref: torch.Tensor, points: torch.Tensor, tokens: int, total: int
) -> dict[str, float]:
    """Lift of the attention rows of target tokens ``(T_target, T)`` on the reference tokens whose surface
    points ``(V, 4, H, W)`` lie within one token footprint of theirs (empty when no token has a match)."""
    xyz, valid, footprint = token_points(points, tokens)
    if total != xyz.shape[0] or not math.isfinite(footprint):
        return {}
    near = torch.cdist(xyz[~is_ref], xyz[is_ref]) < footprint
    near &= valid[~is_ref][:, None] & valid[is_ref][None, :]
    rows = near.any(-1)
    if not rows.any():
        return {}
    mass = (target_rows[:, is_ref] * near).sum(-1)[rows]
    chance = near.sum(-1)[rows].float() / total
    return {
        "correspondence_lift": float(mass.sum() / chance.sum()),
        "corresponding_tokens": float(near.sum(-1)[rows].float().mean()),
        "footprint": footprint,  # packet units: the "near" radius
    }


def knn_weights(
    processor: Any,
    attn: Any,
    logits: torch.Tensor,
    query: torch.Tensor,
    kwargs: dict[str, Any],
    sets: int,
    views: int,
    tokens: int,
) -> torch.Tensor:
    """The attention weights ``(T, T)`` (mean over sets and heads) of a ``knn`` set-mixing layer, as
    :func:`~setdiff_bench.models.setdiff.set_mixer.nearest_reference_attention` computes them: each query's
    softmax over its own view's tokens, its ``k`` nearest reference tokens of the other views and the learned
    "no match" key; ``logits`` ``(S, h, T, T)`` already hold the C-map bias.  The "no match" key's share is
    left out, so a row sums to one minus it."""
    total = views * tokens
    references = int(kwargs.get("num_references") or 0)
    view_of = torch.arange(total) // tokens
    allowed = (view_of[:, None] == view_of[None, :]).expand(sets, total, total).clone()
    if kwargs.get("token_points") is not None and references > 0:
        geometry = set_mixer.pool_token_geometry(kwargs["token_points"], tokens).grouped(sets)
        index_of = torch.arange(total)
        set_index = torch.arange(sets)[:, None, None]
        for view in range(views):
            rows = slice(view * tokens, (view + 1) * tokens)
            candidates = index_of[(index_of < references * tokens) & (view_of != view)]
            index, found = set_mixer.nearest_reference_keys(geometry, rows, candidates, processor.neighbours)
            row_index = index_of[rows].expand(sets, -1)[..., None].expand_as(index)
            allowed[set_index.expand_as(index)[found], row_index[found], index[found]] = True
    heads, head_dim = query.shape[1], query.shape[-1]
    spare_key = getattr(attn, set_mixer.NO_MATCH_KEY).reshape(heads, head_dim).to(query.dtype)
    spare = (query * spare_key[None, :, None]).sum(-1, keepdim=True) / head_dim**0.5  # (S, h, T, 1)
    masked = logits.float().masked_fill(~allowed[:, None], -math.inf)
    weights = torch.softmax(torch.cat([masked, spare.float()], dim=-1), dim=-1)[..., :total]
    return weights.mean(dim=(0, 1))


def attention_stats(
    record: list[dict[str, float]],
    points: torch.Tensor,
    references: int,
    true_points: torch.Tensor | None = None,
) -> Callable[[ProcessorCall], ProcessorCall]:
    """A processor that appends, per layer, the statistics listed in the module docstring."""

    def wrap(original: ProcessorCall) -> ProcessorCall:
        def body(
            self: Any, attn: Any, hidden_states: torch.Tensor, num_views: int | None, kwargs: dict[str, Any]
        ) -> torch.Tensor:
            assert num_views is not None
            views, tokens = num_views, hidden_states.shape[1]
            sets, heads = hidden_states.shape[0] // views, attn.heads
            query, key = attn.to_q(hidden_states), attn.to_k(hidden_states)
            dim = query.shape[-1] // heads
            query = query.reshape(sets, views * tokens, heads, dim).transpose(1, 2)
            key = key.reshape(sets, views * tokens, heads, dim).transpose(1, 2)
            logits = query @ key.transpose(-1, -2) / dim**0.5
            content_logit_std = float(logits.float().std(dim=-1).mean())
            log_scale = getattr(attn, set_mixer.BIAS_PARAMETER, None)
            if kwargs.get("token_points") is not None and log_scale is not None:  # the C-map distance bias
                geometry = set_mixer.pool_token_geometry(kwargs["token_points"], tokens).grouped(sets)
                if getattr(self, "relative_bias", False):
                    logits = logits + set_mixer.relative_distance_bias(geometry, log_scale.exp())
                else:
                    logits = logits + set_mixer.distance_bias(
                        geometry.points, geometry.valid, log_scale.exp()
                    )
            if getattr(self, "attention", "full") == "knn":
                weights = knn_weights(self, attn, logits, query, kwargs, sets, views, tokens)
            else:  # (T, T), the mean over sets and heads
                weights = torch.softmax(logits.float(), dim=-1).mean(dim=(0, 1))
            total = views * tokens
            view_of = torch.arange(total) // tokens
            own = (view_of[:, None] == view_of[None, :]).float()
            entropy = -(weights * torch.log(weights.clamp_min(1e-30))).sum(-1).mean()
            stats = {
                "tokens_per_view": float(tokens),
                "own_view": float((weights * own).sum(-1).mean()),
                "entropy": float(entropy / math.log(total)),
                "content_logit_std": content_logit_std,
                "query_key_weight_norm": float(attn.to_q.weight.norm() * attn.to_k.weight.norm()),
            }
            is_ref = view_of < references
            target_rows = weights[~is_ref]
            if references > 0 and target_rows.numel():
                share = references / views
                stats["reference_mass"] = float(target_rows[:, is_ref].sum(-1).mean() / share)
                stats.update(correspondence(target_rows, is_ref, points, tokens, total))
                if true_points is not None:
                    true = correspondence(target_rows, is_ref, true_points, tokens, total)
                    if "correspondence_lift" in true:
                        stats["correspondence_lift_true"] = true["correspondence_lift"]
            record.append(stats)
            return original(self, attn, hidden_states, num_views=num_views, **kwargs)

        return processor_call(body)

    return wrap


def set_mixer_drift(model: Any, config: Any) -> dict[str, float]:
    """Relative change ``‖W − W0‖ / ‖W0‖`` (Frobenius) of every set-mixer projection from W0, the
    initial weights training built from the same config and seed (:func:`train.initial_model`; a
    different start would give ≈ √2)."""
    initial = dict(initial_model(config.model, config.train.seed).unet.named_parameters())
    drift = {}
    for name, trained in model.unet.named_parameters():
        if ".attn1." in name and name.endswith(".weight") and name in initial:
            start = initial[name].detach()
            drift[name] = round(float((trained.detach() - start).norm() / start.norm()), 4)
    return drift


def mean_psnr(images: torch.Tensor, gt: torch.Tensor, masks: torch.Tensor) -> float:
    """Mean over targets of the masked PSNR (dB) of ``(M, 3, H, W)`` images against their ground truth."""
    return float(psnr(images.clamp(0, 1), gt, masks).mean())


def scene_of(packet_id: str) -> str:
    """``dataset__scene__group__index`` → ``scene``."""
    return packet_id.split("__")[1]


def spread_over_scenes(ids: list[str], count: int) -> list[str]:
    """Up to ``count`` packets, taken from the scenes in turn (first packets first)."""
    by_scene: dict[str, list[str]] = {}
    for packet_id in ids:
        by_scene.setdefault(scene_of(packet_id), []).append(packet_id)
    chosen: list[str] = []
    for rank in range(max((len(v) for v in by_scene.values()), default=0)):
        chosen += [v[rank] for v in by_scene.values() if rank < len(v)]
    return chosen[:count]


def other_scene_packet(packet_id: str, ids: list[str]) -> str | None:
    """The packet of the same group and index in the next other scene (cyclically), else its first."""
    scenes = sorted({scene_of(i) for i in ids})
    here = scene_of(packet_id)
    at = scenes.index(here)
    for scene in scenes[at + 1 :] + scenes[:at]:
        candidates = [i for i in ids if scene_of(i) == scene]
        same_index = [i for i in candidates if i.rsplit("__", 1)[-1] == packet_id.rsplit("__", 1)[-1]]
        if same_index or candidates:
            return (same_index or candidates)[0]
    return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--packets", required=True, help="packet store")
    parser.add_argument(
        "--checkpoint", required=True, help="checkpoint folder or shipped name (tiny_setdiff)"
    )
    parser.add_argument("--group", default="lane+2")
    parser.add_argument("--packets-max", type=int, default=2)
    parser.add_argument("--true-packets", help="the store's true-geometry twin: lift on true correspondences")
    parser.add_argument(
        "--other-scene", action="store_true", help="control: references of another test scene's packet"
    )
    parser.add_argument("--out", type=Path, help="also write the JSON here")
    args = parser.parse_args()
    torch.set_num_threads(1)
    store = PacketStore(args.packets)
    model, config = load_model(args.checkpoint)[:2]
    model = model.eval()
    group_ids = [pid for pid in store.packet_ids("test") if f"__{args.group}__" in pid]
    ids = spread_over_scenes(group_ids, args.packets_max)
    twin = PacketStore(args.true_packets) if args.true_packets else None
    rows = []
    with torch.no_grad():
        for packet_id in ids:
            packet = store.load_packet(packet_id)
            full = enhance_packet(model, packet)
            row: dict[str, Any] = {
                "packet": packet_id,
                "references": len(packet.references),
                "targets": len(packet.targets),
            }
            gt, masks = store.load_ground_truth(packet_id)
            row["psnr_full"] = mean_psnr(full, gt, masks)
            row["psnr_render"] = mean_psnr(packet.targets.images.float(), gt, masks)
            row["psnr_no_references"] = mean_psnr(enhance_packet(model, packet, max_references=0), gt, masks)
            if args.other_scene:
                donor_id = other_scene_packet(packet_id, group_ids)
                if donor_id is not None:
                    swapped = dataclasses.replace(packet, references=store.load_packet(donor_id).references)
                    other = enhance_packet(model, swapped)
                    row["other_scene_references"] = donor_id
                    row["psnr_other_scene_references"] = mean_psnr(other, gt, masks)
                    row["mean_abs_change_other_scene_references"] = float((other - full).abs().mean())
            for refs in (0, 1, 3):
                smaller = enhance_packet(model, packet, max_references=refs, targets_per_set=1)
                row[f"mean_abs_change_{refs}+1"] = float((smaller - full).abs().mean())
            with patched_set_attention(zeroed):
                row["mean_abs_change_no_self_attention"] = float(
                    (enhance_packet(model, packet) - full).abs().mean()
                )
            original_to_x0 = model.to_x0
            model.to_x0 = lambda latents, prediction: latents  # type: ignore[method-assign]
            try:
                row["mean_abs_change_no_unet"] = float((enhance_packet(model, packet) - full).abs().mean())
            finally:
                model.to_x0 = original_to_x0  # type: ignore[method-assign]
            stats: list[dict[str, float]] = []
            points = surface_points(packet)
            true_points = surface_points(twin.load_packet(packet_id)) if twin is not None else None
            with patched_set_attention(attention_stats(stats, points, len(packet.references), true_points)):
                enhance_packet(
                    model,
                    packet,
                    guidance_scale=1.0,
                    targets_per_set=len(packet.targets),
                    max_references=len(packet.references),
                )
            row["layers"] = [{k: round(v, 4) for k, v in layer.items()} for layer in stats]
            row["uniform_over_views"] = round(1.0 / (len(packet.references) + len(packet.targets)), 4)
            rows.append(row)
    text = json.dumps(
        {
            "checkpoint": args.checkpoint,
            "packets": str(args.packets),
            "group": args.group,
            "true_packets": args.true_packets,
            "set_mixer_drift_from_init": set_mixer_drift(model, config),
            "rows": rows,
        },
        indent=1,
    )
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
