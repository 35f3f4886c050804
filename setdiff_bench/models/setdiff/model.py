"""The SetDiff model (and DiFix on the same code): one-step set diffusion on SD-Turbo latents.

Forward pass for B sets of N references + M targets (paper §3.1–3.3; docs/model.md, "One-step formulation"
and "Geometry encoder and guidance"):

1. every view is encoded by the frozen VAE encoder: ``z = mean(E(x)) · 0.18215``;
2. Ψ(C-map, Plücker) is added: the UNet input is ``z + g`` (``g = 0`` when geometry is dropped);
3. the UNet runs **once** at t = 199 (τ = 200) on the clean latents — no noise is added — with the
   set mixer joining all V views' self-attention tokens and the fixed text embedding in ``attn2``;
4. the prediction becomes x̂0 analytically with ᾱ = ᾱ₁₉₉ = 0.7552384 (float64 cumprod of SD-Turbo's
   ``scaled_linear`` betas):  v-prediction ``x̂0 = √ᾱ·z − √(1−ᾱ)·v̂``, ε-prediction
   ``x̂0 = (z − √(1−ᾱ)·ε̂)/√ᾱ``.  ``z`` here is the *image* latent: Ψ's output is a condition added
   to the UNet input, not part of the diffusion state (our reading; with Ψ zero-initialised both
   readings agree at the start);
5. only the targets' x̂0 are decoded (decoder with LoRA, optional DiFix skip convs).

With ``output_mode = "residual"`` (models trained from scratch) the UNet's output conv starts at
zero, ``x̂0 = z − √(1−ᾱ)·û`` and a target's image is ``clamp(render + D(x̂0) − D(z), 0, 1)`` (both
latents decoded in one call with the same skips): an untrained model returns its input exactly, and
training learns the correction only.  With ``attention_bias = "cmap_distance"`` the set mixer's
logits get a C-map distance bias (:func:`.set_mixer.distance_bias`), in every set-mixing layer or, with
``attention_bias_layers = "lowest"``, only in those at the lowest resolution; the points travel with each
UNet call and are removed, like Ψ's output, for the unconditional CFG branch and dropped sets.

Geometry classifier-free guidance: training removes C-maps and poses together for a whole set with
probability ``geometry_dropout``; at inference ``x̂0 = x̂0_u + s·(x̂0_c − x̂0_u)`` with s = 2.0, the
conditional and unconditional UNet passes batched into one call (``cfg_batched``).  As both branches
share ``z``, guiding x̂0 equals guiding the UNet output.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import torch
from torch import nn

from setdiff_bench.models.setdiff.config import ModelConfig
from setdiff_bench.models.setdiff.geometry_encoder import GeometryEncoder
from setdiff_bench.models.setdiff.inputs import SetBatch, check_image_size
from setdiff_bench.models.setdiff.networks import build_networks
from setdiff_bench.models.setdiff.set_mixer import (
    BIAS_INITIAL_SCALE,
    RELATIVE_BIAS_INITIAL_SCALE,
    add_bias_parameters,
    biased_layers,
    install_set_mixer,
    set_kwargs,
)
from setdiff_bench.models.setdiff.vae_codec import Encoded, LatentCodec

#: Pixels (views × H × W) that the VAE encoder, Ψ and the decoder take per call at inference.  They work
#: view by view at full resolution, so a 16-view 576×1024 set in one call would hold gigabytes of
#: activations; in chunks of this many pixels their peak memory is bounded whatever the set size (the
#: UNet still sees the whole set at once).  2 Mi pixels = three 576×1024 views; every set of the
#: 256×144 driving demo fits one chunk.
INFERENCE_CHUNK_PIXELS = 1 << 21


def views_per_chunk(height: int, width: int) -> int:
    """Views per encoder / Ψ / decoder call at inference for ``height × width`` images (at least one)."""
    return max(1, INFERENCE_CHUNK_PIXELS // max(1, height * width))


def view_chunks(count: int, size: int) -> list[slice]:
    """``range(count)`` as consecutive slices of at most ``size``."""
    return [slice(start, min(start + size, count)) for start in range(0, count, size)]


@dataclass
class SetPrediction:
    """Training forward output.

    Attributes:
        target_x0: ``(B, M, C, h, w)`` predicted clean target latents (scaled latent space).
        decoded: ``(B, K, 3, H, W)`` decoded images in [0, 1] of the targets in ``decode_index``,
            or ``None`` when nothing was decoded.
    """

    target_x0: torch.Tensor
    decoded: torch.Tensor | None


class SetDiffModel(nn.Module):
    """SD-Turbo UNet + VAE with set mixer, geometry encoder and one-step x̂0 (see module docstring).

    Args:
        config: the model configuration.
        load_pretrained: load ``config.pretrained`` when set; ``False`` builds random networks of the
            same architecture (used before loading a checkpoint, which holds every weight).
    """

    def __init__(self, config: ModelConfig, *, load_pretrained: bool = True) -> None:
        super().__init__()
        networks = build_networks(config, load_pretrained=load_pretrained)
        self.unet = networks.unet
        self.mixed_attention = install_set_mixer(
            self.unet,
            config.set_attention,
            neighbours=config.set_attention_neighbours,
            relative_bias=config.attention_bias == "cmap_relative",
        )
        if config.attention_bias != "none":
            levels = len(self.unet.down_blocks)
            add_bias_parameters(
                self.unet,
                biased_layers(self.mixed_attention, levels, config.attention_bias_layers),
                RELATIVE_BIAS_INITIAL_SCALE
                if config.attention_bias == "cmap_relative"
                else BIAS_INITIAL_SCALE,
            )
        if config.output_mode == "residual":
            nn.init.zeros_(self.unet.conv_out.weight)
            nn.init.zeros_(self.unet.conv_out.bias)
        self.codec = LatentCodec(
            networks.vae,
            skip_connections=config.skip_connections,
            skip_gamma=config.skip_gamma,
            decoder_training=config.vae_decoder,
            lora_rank=config.vae_lora_rank,
            lora_alpha=config.vae_lora_alpha,
        )
        self.geometry_encoder = (
            GeometryEncoder(
                config.geometry_channels, config.latent_channels, config.latent_factor, config.geometry_groups
            )
            if config.use_geometry
            else None
        )
        text_shape = (1, config.text_length, config.cross_attention_dim)
        prompt = networks.prompt_embedding
        if prompt is not None and tuple(prompt.shape) != text_shape:
            raise ValueError(f"prompt embedding {tuple(prompt.shape)} != {text_shape}")
        learn_text = prompt is None if config.learn_text_embedding is None else config.learn_text_embedding
        initial = torch.zeros(text_shape) if prompt is None else prompt.clone()
        self.text_embedding = nn.Parameter(initial, requires_grad=learn_text)
        self.unet.requires_grad_(True)
        self.config = replace(config, learn_text_embedding=learn_text)
        alpha_bar = config.alpha_bar
        self.sqrt_alpha_bar = math.sqrt(alpha_bar)
        self.sqrt_one_minus_alpha_bar = math.sqrt(1.0 - alpha_bar)

    # ------------------------------------------------------------------ stages
    def encode(self, images: torch.Tensor, keep_skips: torch.Tensor | None = None) -> Encoded:
        """``(B·V, 3, H, W)`` in [0, 1] → :class:`Encoded` (scaled posterior means, skips of ``keep_skips``)."""
        check_image_size(
            int(images.shape[-2]), int(images.shape[-1]), self.config.latent_factor, "model input"
        )
        return self.codec.encode(images, keep_skips)

    def geometry_latents(self, geometry: torch.Tensor) -> torch.Tensor:
        """Ψ: ``(B·V, 9, H, W)`` → ``(B·V, C, H/8, W/8)``."""
        if self.geometry_encoder is None:
            raise RuntimeError("this model has no geometry encoder (use_geometry = false)")
        return self.geometry_encoder(geometry)

    def unet_output(
        self,
        unet_input: torch.Tensor,
        num_views: int,
        points: torch.Tensor | None = None,
        num_references: int | None = None,
    ) -> torch.Tensor:
        """One UNet pass at the fixed timestep over ``(B·V, C, h, w)`` sets of ``num_views`` views
        (``points``: ``(B·V, 4 or 5, h, w)`` latent-cell surface points for the attention bias or ``knn``
        levels, or ``None``; ``num_references``: N, needed by ``knn`` levels)."""
        text = self.text_embedding.to(unet_input.dtype).expand(unet_input.shape[0], -1, -1)
        timestep = torch.full(
            (unet_input.shape[0],), self.config.timestep, device=unet_input.device, dtype=torch.long
        )
        return self.unet(
            unet_input,
            timestep,
            encoder_hidden_states=text,
            cross_attention_kwargs=set_kwargs(num_views, points, num_references),
        ).sample

    def latent_points(self, points: torch.Tensor | None) -> torch.Tensor | None:
        """Pixel surface points ``(B·V, 4 or 5, H, W)`` → latent cells ``(B·V, 4 or 5, H/8, W/8)`` (area means;
        a pixel footprint channel becomes the cell's: × the latent factor), or ``None`` when the set mixer
        uses no points."""
        if points is None or not self.config.needs_points:
            return None
        factor = self.config.latent_factor
        cells = torch.nn.functional.avg_pool2d(points.float(), factor) if factor > 1 else points.float()
        if cells.shape[1] > 4:
            cells = torch.cat([cells[:, :4], cells[:, 4:] * factor], dim=1)
        return cells

    def to_x0(self, latents: torch.Tensor, prediction: torch.Tensor) -> torch.Tensor:
        """Analytic one-step x̂0 from the image latent and the UNet output (v or ε; residual: a correction)."""
        if self.config.output_mode == "residual":
            return latents - self.sqrt_one_minus_alpha_bar * prediction
        if self.config.prediction == "v_prediction":
            return self.sqrt_alpha_bar * latents - self.sqrt_one_minus_alpha_bar * prediction
        return (latents - self.sqrt_one_minus_alpha_bar * prediction) / self.sqrt_alpha_bar

    def decode(self, latents: torch.Tensor, skips: tuple[torch.Tensor, ...] | None = None) -> torch.Tensor:
        """Scaled latents ``(K, C, h, w)`` → images ``(K, 3, H, W)`` in [0, 1]."""
        return self.codec.decode(latents, skips)

    def output_images(
        self,
        x0: torch.Tensor,
        latents: torch.Tensor,
        renders: torch.Tensor,
        skips: tuple[torch.Tensor, ...] | None,
    ) -> torch.Tensor:
        """The enhanced images ``(K, 3, H, W)`` of K targets from their x̂0 ``(K, C, h, w)``.

        ``direct``: ``D(x̂0)``.  ``residual``: ``clamp(render + D(x̂0) − D(z), 0, 1)`` with ``z`` the
        render's latent ``(K, C, h, w)`` and ``renders`` ``(K, 3, H, W)``, both decoded in one call.
        """
        if self.config.output_mode == "direct":
            return self.decode(x0, skips)
        doubled = None if skips is None else tuple(torch.cat([s, s]) for s in skips)
        changed, unchanged = self.decode(torch.cat([x0, latents.to(x0.dtype)]), doubled).chunk(2)
        return (renders.to(changed.dtype) + changed - unchanged).clamp(0.0, 1.0)

    def predict_x0(
        self,
        latents: torch.Tensor,
        geometry: torch.Tensor | None,
        num_views: int,
        *,
        guidance_scale: float = 1.0,
        geometry_keep: torch.Tensor | None = None,
        points: torch.Tensor | None = None,
        view_chunk: int | None = None,
        num_references: int | None = None,
    ) -> torch.Tensor:
        """x̂0 for every view, ``(B·V, C, h, w)``.

        Args:
            latents: ``(B·V, C, h, w)`` image latents.
            geometry: ``(B·V, 9, H, W)`` Ψ input or ``None`` (no geometry).
            guidance_scale: geometry CFG scale; 1 = conditional only.
            geometry_keep: ``(B,)`` 0/1 per set multiplying Ψ's output (training dropout); the
                multiplication keeps Ψ in the graph so DDP sees all parameters used.
            points: ``(B·V, 4, H, W)`` pixel surface points for the attention bias (or ``None``);
                dropped with the geometry.
            view_chunk: run Ψ on this many views per call (``None`` = all at once).
            num_references: N, the references at the start of each set (needed by ``knn`` levels).
        """
        n = num_references
        if geometry is None or self.geometry_encoder is None:
            return self.to_x0(latents, self.unet_output(latents, num_views, num_references=n))
        chunks = view_chunks(geometry.shape[0], view_chunk or geometry.shape[0])
        g = torch.cat([self.geometry_latents(geometry[chunk].to(latents.dtype)) for chunk in chunks])
        cells = self.latent_points(points)
        if geometry_keep is not None:
            keep = geometry_keep.to(g.dtype).repeat_interleave(num_views)
            g = g * keep.view(-1, 1, 1, 1)
            if cells is not None:
                cells = cells * keep.view(-1, 1, 1, 1).to(cells.dtype)
        if guidance_scale == 1.0:
            return self.to_x0(latents, self.unet_output(latents + g, num_views, cells, n))
        if self.config.cfg_batched:
            both_cells = None if cells is None else torch.cat([cells, torch.zeros_like(cells)])
            both = self.unet_output(torch.cat([latents + g, latents]), num_views, both_cells, n)
            conditional, unconditional = both.chunk(2)
        else:
            conditional = self.unet_output(latents + g, num_views, cells, n)
            unconditional = self.unet_output(latents, num_views, num_references=n)
        guided = unconditional + guidance_scale * (conditional - unconditional)
        return self.to_x0(latents, guided)

    # ------------------------------------------------------------------ whole passes
    def forward(
        self,
        batch: SetBatch,
        *,
        geometry_keep: torch.Tensor | None = None,
        decode_index: torch.Tensor | None = None,
        guidance_scale: float = 1.0,
    ) -> SetPrediction:
        """Training pass (no CFG by default): x̂0 of all targets, and decoded images of ``decode_index`` targets.

        Args:
            batch: B sets of N references + M targets.
            geometry_keep: ``(B,)`` 0/1 geometry dropout per set (``None`` = keep all).
            decode_index: target indices (in ``[0, M)``, same for all sets) to decode; ``None`` = none.
            guidance_scale: geometry CFG scale (a distillation teacher's targets, :mod:`.distill`); 1 = one pass.
        """
        sets, views, n = batch.num_sets, batch.num_views, batch.num_references
        images, geometry, points = _merged_views(batch)
        flat_decode = None
        if decode_index is not None:
            offsets = torch.arange(sets, device=decode_index.device)[:, None] * views
            flat_decode = (offsets + n + decode_index[None, :].to(offsets.device)).reshape(-1)
        encoded = self.encode(images, flat_decode)
        x0 = self.predict_x0(
            encoded.latents,
            geometry,
            views,
            guidance_scale=guidance_scale,
            geometry_keep=geometry_keep,
            points=points,
            num_references=n,
        )
        x0 = x0.reshape(sets, views, *x0.shape[1:])
        target_x0 = x0[:, n:]
        decoded = None
        if flat_decode is not None:
            chosen = flat_decode.to(x0.device)
            decoded = self.output_images(
                x0.reshape(sets * views, *x0.shape[2:])[chosen],
                encoded.latents[chosen],
                images[chosen],
                encoded.skips,
            )
            decoded = decoded.reshape(sets, -1, *decoded.shape[1:])
        return SetPrediction(target_x0=target_x0, decoded=decoded)

    @torch.no_grad()
    def enhance(self, batch: SetBatch, guidance_scale: float | None = None) -> torch.Tensor:
        """Inference: ``(B, M, 3, H, W)`` enhanced targets in [0, 1] (CFG per the config).

        Args:
            guidance_scale: overrides ``config.guidance_scale`` (ignored without geometry).
        """
        scale = self.config.guidance_scale if guidance_scale is None else float(guidance_scale)
        sets, views, n = batch.num_sets, batch.num_views, batch.num_references
        images, geometry, points = _merged_views(batch)
        targets = (torch.arange(sets)[:, None] * views + torch.arange(n, views)[None, :]).reshape(-1)
        chunk = views_per_chunk(int(images.shape[-2]), int(images.shape[-1]))
        encoded = self._encode_in_chunks(images, targets.to(images.device), chunk)
        x0 = self.predict_x0(
            encoded.latents,
            geometry,
            views,
            guidance_scale=scale,
            points=points,
            view_chunk=chunk,
            num_references=n,
        )
        chosen = targets.to(x0.device)
        target_skips = encoded.skips
        decoded = torch.cat(
            [
                self.output_images(
                    x0[chosen[part]],
                    encoded.latents[chosen[part]],
                    images[chosen[part]],
                    None if target_skips is None else tuple(skip[part] for skip in target_skips),
                )
                for part in view_chunks(len(chosen), max(1, chunk // 2))  # residual decodes twice
            ]
        )
        return decoded.reshape(sets, views - n, *decoded.shape[1:]).float()

    def _encode_in_chunks(self, images: torch.Tensor, keep_skips: torch.Tensor, chunk: int) -> Encoded:
        """:meth:`encode` of ``(V, 3, H, W)`` images ``chunk`` views per call; the skips of
        ``keep_skips`` (ascending indices into V) come back in that order."""
        if chunk >= images.shape[0]:
            return self.encode(images, keep_skips)
        parts = []
        for views in view_chunks(images.shape[0], chunk):
            local = keep_skips[(keep_skips >= views.start) & (keep_skips < views.stop)] - views.start
            parts.append(self.encode(images[views], local))
        latents = torch.cat([part.latents for part in parts])
        if parts[0].skips is None:
            return Encoded(latents=latents, skips=None)
        levels = len(parts[0].skips)
        skips = tuple(
            torch.cat([part.skips[level] for part in parts if part.skips]) for level in range(levels)
        )
        return Encoded(latents=latents, skips=skips)

    def trainable_parameters(self) -> list[nn.Parameter]:
        """UNet (fully), Ψ, the decoder per ``vae_decoder`` (LoRA/full), skip convs, a learned text embedding."""
        return [p for p in self.parameters() if p.requires_grad]


def _merged_views(batch: SetBatch) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor | None]:
    """``(images, geometry, points)`` of ``batch`` with its set and view axes merged: ``(B, V, ...)`` →
    ``(B·V, ...)`` (``None`` stays ``None``)."""

    flat = batch.num_sets * batch.num_views

    def merged(x: torch.Tensor | None) -> torch.Tensor | None:
        return None if x is None else x.reshape(flat, *x.shape[2:])

    return batch.images.reshape(flat, *batch.images.shape[2:]), merged(batch.geometry), merged(batch.points)
