"""The VAE as SetDiff uses it: a frozen encoder (posterior mean), a decoder with LoRA and optional skips.

``LatentCodec`` wraps a diffusers ``AutoencoderKL``:

* ``encode``: images in [0, 1] → ``posterior mean × scaling_factor`` (the encoder is frozen and runs
  without gradients), optionally keeping the input of every encoder down block for the skips.
* ``decode``: scaled latents → images in [0, 1] (``clamp(-1, 1)`` as DiFix3D), adding
  ``skip_conv_i(γ · skip)`` before each decoder up block when skip connections are on — the DiFix3D /
  img2img-turbo design (1×1 convs without bias, weights initialised to 1e-5; docs/model.md,
  "DiFix VAE skip connections").

The encoder and decoder are walked block by block here instead of patching diffusers' ``forward``
methods (what DiFix3D does globally); the walk mirrors diffusers' ``Encoder.forward`` /
``Decoder.forward`` without gradient checkpointing, and a test checks it against ``vae.encode`` /
``vae.decode``.

Decoder training (``vae_decoder``): ``lora`` adds peft LoRA (rank r, gaussian init, so the decoder is
unchanged at start) to the decoder's convs and attention projections — the DiFix3D target list
``conv1 conv2 conv_in conv_shortcut conv conv_out to_q to_k to_v to_out.0`` restricted to the decoder;
``full`` trains the whole decoder; ``frozen`` trains nothing.  Skip convs, when present, are always
fully trainable (DiFix3D also puts LoRA on them, which is redundant for a trainable layer).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch
from torch import nn

LORA_ADAPTER = "vae_decoder"
LORA_SUFFIXES = (
    "conv1",
    "conv2",
    "conv_in",
    "conv_shortcut",
    "conv",
    "conv_out",
    "to_q",
    "to_k",
    "to_v",
    "to_out.0",
)
SKIP_INIT = 1e-5


@dataclass
class Encoded:
    """Output of :meth:`LatentCodec.encode`.

    Attributes:
        latents: ``(V, C, H/8, W/8)`` scaled posterior means.
        skips: for the views in ``keep_skips``: the inputs of the encoder's down blocks, outermost
            first (``(K, 128, H, W)``, ``(K, 128, H/2, W/2)``, ... for SD); ``None`` when not kept.
    """

    latents: torch.Tensor
    skips: tuple[torch.Tensor, ...] | None


class LatentCodec(nn.Module):
    """Frozen-encoder / trainable-decoder VAE wrapper (see the module docstring)."""

    def __init__(
        self,
        vae: Any,
        *,
        skip_connections: bool,
        skip_gamma: float = 1.0,
        decoder_training: str = "lora",
        lora_rank: int = 4,
        lora_alpha: float = 8.0,
    ) -> None:
        super().__init__()
        self.vae = vae
        self.scaling_factor = float(vae.config.scaling_factor)
        self.shift_factor = float(vae.config.shift_factor or 0.0)
        self.skip_gamma = float(skip_gamma)
        self.decoder_training = decoder_training
        self.skip_convs: nn.ModuleList | None = None
        if skip_connections:
            encoder_in = [int(block.resnets[0].in_channels) for block in vae.encoder.down_blocks][::-1]
            decoder_in = [int(block.resnets[0].in_channels) for block in vae.decoder.up_blocks]
            self.skip_convs = nn.ModuleList(
                nn.Conv2d(c_in, c_out, kernel_size=1, bias=False)
                for c_in, c_out in zip(encoder_in, decoder_in)
            )
            for conv in self.skip_convs:
                nn.init.constant_(conv.weight, SKIP_INIT)
        if decoder_training == "lora":
            self._add_decoder_lora(lora_rank, lora_alpha)
        self._set_trainable()

    def _add_decoder_lora(self, rank: int, alpha: float) -> None:
        from peft import LoraConfig

        targets = [
            name
            for name, module in self.vae.named_modules()
            if name.startswith("decoder.")
            and isinstance(module, nn.Conv2d | nn.Linear)
            and any(name == suffix or name.endswith("." + suffix) for suffix in LORA_SUFFIXES)
        ]
        config = LoraConfig(r=rank, lora_alpha=alpha, init_lora_weights="gaussian", target_modules=targets)
        self.vae.add_adapter(config, adapter_name=LORA_ADAPTER)

    def _set_trainable(self) -> None:
        self.vae.requires_grad_(False)
        if self.decoder_training == "full":
            self.vae.decoder.requires_grad_(True)
            if self.vae.post_quant_conv is not None:
                self.vae.post_quant_conv.requires_grad_(True)
        elif self.decoder_training == "lora":
            for name, parameter in self.vae.named_parameters():
                if "lora_" in name:
                    parameter.requires_grad_(True)
        if self.skip_convs is not None:
            self.skip_convs.requires_grad_(True)

    @property
    def latent_channels(self) -> int:
        return int(self.vae.config.latent_channels)

    @torch.no_grad()
    def encode(self, images: torch.Tensor, keep_skips: torch.Tensor | None = None) -> Encoded:
        """``images`` ``(V, 3, H, W)`` in [0, 1] → scaled posterior means ``(V, C, H/8, W/8)``.

        Args:
            keep_skips: indices (into V) of the views whose down-block inputs are kept for the
                decoder skips; ignored without skip connections.
        """
        encoder = self.vae.encoder
        keep = keep_skips if self.skip_convs is not None else None
        sample = encoder.conv_in(images * 2.0 - 1.0)
        skips: list[torch.Tensor] = []
        for block in encoder.down_blocks:
            if keep is not None:
                skips.append(sample[keep])
            sample = block(sample)
        sample = encoder.mid_block(sample)
        sample = encoder.conv_out(encoder.conv_act(encoder.conv_norm_out(sample)))
        if self.vae.quant_conv is not None:
            sample = self.vae.quant_conv(sample)
        mean = sample[:, : self.latent_channels]
        latents = (mean - self.shift_factor) * self.scaling_factor
        return Encoded(latents=latents, skips=tuple(skips) if keep is not None else None)

    def decode(self, latents: torch.Tensor, skips: tuple[torch.Tensor, ...] | None = None) -> torch.Tensor:
        """Scaled latents ``(K, C, h, w)`` → images ``(K, 3, 8h, 8w)`` in [0, 1].

        ``skips`` are the matching views' encoder activations (required with skip connections).
        """
        if self.skip_convs is not None and skips is None:
            raise ValueError(
                "this decoder has skip connections: pass the encoder activations of the same views"
            )
        decoder = self.vae.decoder
        sample = latents / self.scaling_factor + self.shift_factor
        if self.vae.post_quant_conv is not None:
            sample = self.vae.post_quant_conv(sample)
        sample = decoder.conv_in(sample)
        sample = decoder.mid_block(sample, None)
        for index, block in enumerate(decoder.up_blocks):
            if self.skip_convs is not None and skips is not None:
                skip = skips[len(skips) - 1 - index]
                sample = sample + self.skip_convs[index](skip * self.skip_gamma)
            sample = block(sample, None)
        sample = decoder.conv_out(decoder.conv_act(decoder.conv_norm_out(sample)))
        return (sample.clamp(-1.0, 1.0) + 1.0) / 2.0
