"""The settings of ``setdiff-bench train autoencoder`` (:class:`AutoencoderTraining`), apart from the
training code so that the command line reads their defaults without importing torch."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class AutoencoderTraining:
    """Hyper-parameters of :func:`train_autoencoder` (all recorded in the manifest).

    The defaults are the recipe of the shipped ``tiny_autoencoder`` (31.25 dB on the 288 test frames of the
    shipped models' store): about 3 min on one H200, about 5 h on 2 CPU cores; ``--steps 1200 --crop 64
    --batch-size 8 --latent-channels 8`` gives a 24 dB one in about 4 min on one CPU thread.

    Attributes:
        steps: optimiser steps.
        batch_size: crops per step.
        crop: square crop side in pixels (a multiple of 8; clipped to the frame).
        learning_rate: AdamW learning rate (cosine-decayed to 5 % over ``steps``).
        kl_weight: weight of the posterior's KL term (keeps the latent bounded; SD used 1e-6).
        latent_channels: latent channels of the VAE (SD's VAE has 4; more keep more detail).
        base_channels: width of the VAE's first block; its blocks have ``(c, 2c, 2c, 2c)`` channels
            (the tiny preset's VAE is ``c = 16``; compute per pixel grows about as ``c²``).
        seed: seeds initialisation, crops and flips.
        checkpoint_every: save the training state every this many steps (resume point).
    """

    steps: int = 6000
    batch_size: int = 16
    crop: int = 128
    learning_rate: float = 2e-3
    kl_weight: float = 1e-6
    latent_channels: int = 16
    base_channels: int = 16
    seed: int = 0
    checkpoint_every: int = 250
