"""SetDiff / DiFix configuration: the :class:`ModelConfig` and :class:`TrainConfig` dataclasses and how a
``{"model": {...}, "train": {...}}`` table becomes them.

A model config starts from an architecture ``preset`` (the data: :mod:`~setdiff_bench.models.setdiff.presets`)
with ``[model.unet]`` / ``[model.vae]`` overriding single architecture keys; reading and writing config TOML files
(and the packaged examples, named without a path) is :mod:`~setdiff_bench.models.setdiff.config_io`.
"""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any, Literal, get_args

from setdiff_bench.errors import UsageError
from setdiff_bench.io.jsonable import jsonable
from setdiff_bench.models.setdiff.autoencoder import read_autoencoder_config
from setdiff_bench.models.setdiff.methods import Method
from setdiff_bench.models.setdiff.presets import (
    PRESETS,
    SD_TURBO_SCHEDULE,
    SD_TURBO_UNET,
    SD_TURBO_VAE,
    alphas_cumprod,
)

Prediction = Literal["v_prediction", "epsilon"]
DecoderTraining = Literal["lora", "full", "frozen"]
OutputMode = Literal["direct", "residual"]
AttentionBias = Literal["none", "cmap_distance", "cmap_relative"]
SetAttention = Literal["full", "view", "knn"]
AttentionBiasLayers = Literal["all", "lowest"]
MixedPrecision = Literal["auto", "no", "bf16", "fp16"]
LpipsNet = Literal["vgg", "alex"]
SetShape = Literal["proportional", "test"]

#: Field metadata of the :class:`ModelConfig` fields that decide parameter names and shapes and the forward
#: maths: :meth:`ModelConfig.architecture` (a checkpoint's identity) is made of these fields.
ARCHITECTURE: Mapping[str, bool] = {"architecture": True}

CONFIG_FORMAT = 1
DEFAULT_PROMPT = "remove degradation"


@dataclass(frozen=True)
class ModelConfig:
    """Everything that defines the model's parameters and its forward pass.

    Attributes:
        method: ``setdiff`` (set of N refs + M targets, geometry, CFG) or ``difix`` (one reference +
            one target, RGB only, no CFG — the DiFix3D baseline on the same code).
        preset: the architecture the ``unet``/``vae`` dicts started from (``sd-turbo`` or ``tiny``).
        unet, vae: diffusers ``UNet2DConditionModel`` / ``AutoencoderKL`` configs.
        scheduler: ``beta_start``, ``beta_end``, ``beta_schedule``, ``num_train_timesteps``.
        timestep: the fixed UNet timestep (199, i.e. τ = 200); the clean latent is fed, no noise.
        prediction: the UNet output's meaning, ``v_prediction`` (SetDiff) or ``epsilon`` (DiFix, SD-Turbo).
        use_geometry: add Ψ(C-map, Plücker) to the latents.
        geometry_inputs: the cues Ψ sees, a subset of ``("cmap", "plucker")`` (both in the paper; one
            of them for the geometry-grounding ablation, Table 5 — the other's channels are zeroed).
        geometry_channels: the five conv blocks' widths of Ψ.
        geometry_groups: GroupNorm groups in Ψ (clipped to divide each width).
        cmap_clip: C-map coordinates are clamped to ±cmap_clip (packet units; the packet's cameras
            span 1).  The paper "clips by scene scale"; the value is our choice (UNCONFIRMED).  0 = off.
        geometry_dropout: probability, per training packet, of removing C-maps and poses together.
        guidance_scale: geometry CFG scale at inference (1.0 = conditional only, no second pass).
        cfg_batched: run conditional and unconditional passes in one UNet call (2× batch).
        vae_decoder: how the decoder trains: ``lora`` (peft, rank ``vae_lora_rank``), ``full``, ``frozen``.
        vae_lora_rank, vae_lora_alpha: LoRA rank and alpha (peft's default alpha is 8; DiFix keeps it).
        skip_connections: DiFix-style 1×1 skip convs from the encoder's down-block inputs to the decoder.
        skip_gamma: multiplier on the skip activations (DiFix: 1).
        text_prompt: the fixed prompt, encoded once when a text encoder is available.
        text_length: token count of the text embedding (77).
        learn_text_embedding: train the text embedding; ``None`` = automatic: frozen when it is the
            encoded prompt of a pretrained text encoder, learned (from zeros) otherwise.  Resolved to
            ``True``/``False`` when the model is built, and saved so in checkpoints.
        max_references: use at most this many references per set (the first ones); ``None`` = all.
        targets_per_set: enhance targets in sets of this many (DiFix: 1); ``None`` = all at once.
        pretrained: a local diffusers SD-Turbo folder (``unet/``, ``vae/``, ``scheduler/``, optional
            ``text_encoder/`` + ``tokenizer/``) to initialise from; ``None`` = random init.
        autoencoder: a pretrained tiny autoencoder (folder or packaged name, see :mod:`.autoencoder`):
            its VAE config replaces the preset's and its weights are loaded when the model is built
            (the encoder stays frozen, as the paper freezes SD's).  ``None`` = the preset's VAE.
        output_mode: ``direct`` (the paper: x̂0 from the prediction, image = D(x̂0)) or ``residual``
            (identity at initialisation, for models trained from scratch): the UNet's output conv
            starts at zero, ``x̂0 = z − √(1−ᾱ)·û`` and the image is ``clamp(render + D(x̂0) − D(z))``,
            so an untrained model returns its input and training learns only the correction.
        attention_bias: ``none`` (the paper's set mixer) or ``cmap_distance`` (beyond the paper): each
            set-mixer logit gets ``−s·min(‖p_q − p_k‖², cap)`` from the tokens' C-map surface points
            (learnable s ≥ 0 per layer), steering attention to geometrically corresponding tokens.
            ``cmap_relative`` (beyond the paper, scale-free): the same form on ray-snapped points with the
            distance divided by the query token's footprint (its depth × the token's angular size) and
            low-alpha tokens weighted by their surface coverage (:func:`.set_mixer.relative_distance_bias`).
        attention_bias_layers: which set-mixing layers get the bias: ``all``, or ``lowest`` (only those
            at the UNet's lowest resolution, whose few tokens keep the bias cheap; the others keep
            torch's fused attention kernel).
        set_attention: what the set-mixing layers of each resolution level attend to, level 0 (the full
            latent grid) first, levels past the end ``full``: ``full`` (the whole set, the paper), ``view``
            (the own view only) or ``knn`` (the own view, the ``set_attention_neighbours`` reference tokens
            nearest in 3D and a learned "no match" key; beyond the paper, :mod:`.set_mixer`).
        set_attention_neighbours: k of the ``knn`` levels.
    """

    method: Method = field(default="setdiff", metadata=ARCHITECTURE)
    preset: str = "sd-turbo"
    unet: Mapping[str, Any] = field(
        default_factory=lambda: copy.deepcopy(SD_TURBO_UNET), metadata=ARCHITECTURE
    )
    vae: Mapping[str, Any] = field(default_factory=lambda: copy.deepcopy(SD_TURBO_VAE), metadata=ARCHITECTURE)
    scheduler: Mapping[str, Any] = field(
        default_factory=lambda: dict(SD_TURBO_SCHEDULE), metadata=ARCHITECTURE
    )
    timestep: int = field(default=199, metadata=ARCHITECTURE)
    prediction: Prediction = field(default="v_prediction", metadata=ARCHITECTURE)
    use_geometry: bool = field(default=True, metadata=ARCHITECTURE)
    geometry_inputs: tuple[str, ...] = field(default=("cmap", "plucker"), metadata=ARCHITECTURE)
    geometry_channels: tuple[int, ...] = field(default=(32, 64, 128, 256, 256), metadata=ARCHITECTURE)
    geometry_groups: int = field(default=8, metadata=ARCHITECTURE)
    cmap_clip: float = field(default=10.0, metadata=ARCHITECTURE)
    geometry_dropout: float = 0.15
    guidance_scale: float = 2.0
    cfg_batched: bool = True
    vae_decoder: DecoderTraining = field(default="lora", metadata=ARCHITECTURE)
    vae_lora_rank: int = field(default=4, metadata=ARCHITECTURE)
    vae_lora_alpha: float = field(default=8.0, metadata=ARCHITECTURE)
    skip_connections: bool = field(default=False, metadata=ARCHITECTURE)
    skip_gamma: float = field(default=1.0, metadata=ARCHITECTURE)
    text_prompt: str = DEFAULT_PROMPT
    text_length: int = field(default=77, metadata=ARCHITECTURE)
    learn_text_embedding: bool | None = None
    max_references: int | None = None
    targets_per_set: int | None = None
    pretrained: str | None = None
    autoencoder: str | None = None
    output_mode: OutputMode = field(default="direct", metadata=ARCHITECTURE)
    attention_bias: AttentionBias = field(default="none", metadata=ARCHITECTURE)
    attention_bias_layers: AttentionBiasLayers = field(default="all", metadata=ARCHITECTURE)
    set_attention: tuple[str, ...] = field(default=(), metadata=ARCHITECTURE)
    set_attention_neighbours: int = field(default=16, metadata=ARCHITECTURE)

    def __post_init__(self) -> None:
        where = "[model]"
        object.__setattr__(self, "set_attention", tuple(self.set_attention))
        for level in self.set_attention:
            check_choice(level, SetAttention, "set_attention entries", where)
        levels = len(self.unet.get("down_block_types", ()))
        if len(self.set_attention) > levels:
            raise UsageError(
                f"set_attention lists {len(self.set_attention)} levels but the UNet has {levels}", where
            )
        if "knn" in self.set_attention and not self.use_geometry:
            raise UsageError("set_attention 'knn' needs C-maps: set use_geometry = true", where)
        if self.set_attention_neighbours < 1:
            raise UsageError(
                f"set_attention_neighbours must be >= 1, got {self.set_attention_neighbours}", where
            )
        check_choice(self.output_mode, OutputMode, "output_mode", where)
        check_choice(self.attention_bias, AttentionBias, "attention_bias", where)
        check_choice(self.attention_bias_layers, AttentionBiasLayers, "attention_bias_layers", where)
        if self.attention_bias != "none" and not self.use_geometry:
            raise UsageError("attention_bias needs C-maps: set use_geometry = true", where)
        check_choice(self.method, Method, "method", where)
        check_choice(self.prediction, Prediction, "prediction", where)
        check_choice(self.vae_decoder, DecoderTraining, "vae_decoder", where, quoted=False)
        steps = int(self.scheduler["num_train_timesteps"])
        if not 0 <= self.timestep < steps:
            raise UsageError(f"timestep must be in [0, {steps}), got {self.timestep}", where)
        if len(self.geometry_channels) != 5:
            raise UsageError(
                f"geometry_channels must list 5 block widths, got {list(self.geometry_channels)}", where
            )
        inputs = tuple(self.geometry_inputs)
        if not inputs or set(inputs) - {"cmap", "plucker"} or len(set(inputs)) != len(inputs):
            raise UsageError(
                f"geometry_inputs must be a non-empty subset of ['cmap', 'plucker'], got {list(inputs)}"
                " (use use_geometry = false for none)",
                where,
            )
        object.__setattr__(self, "geometry_inputs", inputs)
        check_guidance_scale(self.guidance_scale, where)
        if not 0.0 <= self.geometry_dropout < 1.0:
            raise UsageError(f"geometry_dropout must be in [0, 1), got {self.geometry_dropout}", where)
        if self.max_references is not None and self.max_references < 0:
            raise UsageError(f"max_references must be >= 0, got {self.max_references}", where)
        if self.targets_per_set is not None and self.targets_per_set < 1:
            raise UsageError(f"targets_per_set must be >= 1, got {self.targets_per_set}", where)
        if self.method == "difix":
            bad = []
            if self.use_geometry:
                bad.append("use_geometry = false")
            if self.max_references != 1:
                bad.append("max_references = 1")
            if self.targets_per_set != 1:
                bad.append("targets_per_set = 1")
            if bad:
                raise UsageError(
                    f"method 'difix' is RGB-only with one reference and one target; set {', '.join(bad)}",
                    where,
                )
        factor = self.latent_factor
        if factor & (factor - 1) or factor > 16:
            raise UsageError(f"VAE downsampling factor must be a power of two <= 16, got {factor}", where)
        object.__setattr__(self, "geometry_channels", tuple(int(c) for c in self.geometry_channels))

    @property
    def latent_channels(self) -> int:
        return int(self.vae["latent_channels"])

    @property
    def latent_factor(self) -> int:
        """Image-to-latent downsampling (8 for SD VAEs: one per down block but the last)."""
        return 2 ** (len(self.vae["block_out_channels"]) - 1)

    @property
    def cross_attention_dim(self) -> int:
        return int(self.unet["cross_attention_dim"])

    @property
    def alpha_bar(self) -> float:
        """ᾱ at :attr:`timestep` (0.7552384 for SD-Turbo at t = 199), float64 arithmetic."""
        return float(alphas_cumprod(**self.scheduler)[self.timestep])

    @property
    def needs_points(self) -> bool:
        """The set mixer needs the tokens' C-map surface points (an attention bias or a ``knn`` level)."""
        return self.attention_bias != "none" or "knn" in self.set_attention

    @property
    def snapped_points(self) -> bool:
        """The surface points are ray-snapped and carry footprints (the relative bias)."""
        return self.attention_bias == "cmap_relative"

    @property
    def uses_cfg(self) -> bool:
        return self.use_geometry and self.guidance_scale != 1.0

    def architecture(self) -> dict[str, Any]:
        """The fields that decide parameter names/shapes and the forward maths (checkpoint identity): those
        declared with :data:`ARCHITECTURE` metadata.

        Inference knobs (guidance scale, CFG batching, set sizes) and the ``pretrained`` path are
        left out: a checkpoint may be used with other values of those.
        """
        return jsonable(
            {f.name: getattr(self, f.name) for f in fields(self) if f.metadata.get("architecture")}
        )

    def to_dict(self) -> dict[str, Any]:
        return jsonable(asdict(self))


@dataclass(frozen=True)
class TrainConfig:
    """Training hyper-parameters (paper supplement; DiFix3D defaults where the paper is silent).

    Attributes:
        steps: optimiser steps (the paper: ~40 k at total batch 4).
        learning_rate, weight_decay, adam_betas, adam_eps: AdamW (DiFix: 2e-5, 1e-2, (0.9, 0.999), 1e-8).
        grad_clip: max gradient norm (0 = off).
        gradient_accumulation: micro-batches (one packet each) per optimiser step and process.
        min_views, max_views: each training set holds a random number of views in this range
            (fewer if the packet has fewer); references and targets keep the packet's proportion,
            at least one of each when the packet has them.
        decode_targets: how many target latents are decoded for the reconstruction loss (0 = all).
        latent_weight: weight of the latent loss ‖x̂0 − E(y)‖² on target latents.
        l2_weight, ssim_weight, lpips_weight: reconstruction terms (equal weights in the paper).
        lpips_net: LPIPS backbone for the loss (``vgg`` as DiFix, or ``alex``).
        mixed_precision: ``auto`` (bf16 on CUDA, fp32 on CPU), ``no``, ``bf16`` or ``fp16``.
        checkpoint_every, keep_checkpoints: save period in steps and how many step checkpoints to keep.
        validate_every, validation_packets: validation period and how many test packets it scores.
        log_every: progress-bar update period.
        seed: seeds every random choice (subsets, permutations, dropout, init).
        num_workers: DataLoader worker processes.
        gradient_checkpointing: recompute UNet blocks in the backward pass (less memory, ~30 % slower);
            needed for sets of 8–12 views at 576×1024 on 80 GB GPUs.
        identity_fraction: probability per set of an identity sample (every target's input replaced by
            its ground truth: a clean view must come back unchanged); 0 = off (the paper).
        masked_copy_fraction: probability per set of a masked-copy sample (every target render loses
            a rectangle, its geometry kept, so the content must come from the references); drawn
            after, and exclusive of, the identity sample; 0 = off (the paper).
        masked_copy_visible: a masked-copy hole blanks only pixels whose surface a reference of the set
            sees (depth test on ray-snapped C-map points, :func:`.inputs.reference_visibility`), its
            centre drawn among them; ``False`` = the whole rectangle around a surface pixel (as before).
        set_shape: how a training set is drawn from a sample: ``proportional`` (a random subset of
            ``min_views``–``max_views`` views in the packet's proportion, as before) or ``test`` (shaped like
            a test packet: *all* the sample's references and ``test_targets`` targets).  With ``test``, set
            ``min_views`` and ``max_views`` to at least the largest packet's view count, so that the packet
            store hands over whole packets.
        test_targets: ``(lo, hi)``: a ``test``-shaped set holds a uniform number of targets in this range
            (capped by the sample's).
        sparsest_share: the share of draws taken from the packets with the fewest references (the n3
            packets of the sparse benchmark), the rest from the others, each group in its own seeded
            shuffle (:class:`.sample_stream.SampleStream`); 0 = every packet once per epoch (as before).
        distill_from: guidance distillation (a one-pass student, beyond the paper): the teacher, a
            checkpoint or training folder or a packaged model name.  The student starts from the
            teacher's weights and learns to give, in one conditional pass (``guidance_scale`` 1), the
            teacher's geometry-CFG output; its targets replace the ground truth in every loss term.
            ``None`` = ordinary training.
        distill_guidance_scale: the teacher's CFG scale for the targets; ``None`` = the teacher config's.
            The teacher's architecture must be the student's except for what the set mixer attends to
            (``set_attention``, ``set_attention_neighbours``): a student may restrict it.
        init_from: a fine-tune: start from a trained model's weights (checkpoint or training folder or
            packaged name) and train as usual on the ground truth.  Its architecture must be this config's
            except for what the set mixer attends to, so a model can be re-trained with restricted set
            attention (a ``knn`` level's "no match" key and value start at zero).  ``None`` = from scratch
            (or the pretrained weights the preset loads).  Not with ``distill_from`` (a student already
            starts from its teacher).
    """

    steps: int = 40_000
    learning_rate: float = 2e-5
    weight_decay: float = 1e-2
    adam_betas: tuple[float, float] = (0.9, 0.999)
    adam_eps: float = 1e-8
    grad_clip: float = 1.0
    gradient_accumulation: int = 1
    min_views: int = 8
    max_views: int = 12
    decode_targets: int = 2
    latent_weight: float = 1.0
    l2_weight: float = 1.0
    ssim_weight: float = 1.0
    lpips_weight: float = 1.0
    lpips_net: LpipsNet = "vgg"
    mixed_precision: MixedPrecision = "auto"
    checkpoint_every: int = 1000
    keep_checkpoints: int = 3
    validate_every: int = 1000
    validation_packets: int = 4
    log_every: int = 10
    seed: int = 0
    num_workers: int = 0
    gradient_checkpointing: bool = False
    identity_fraction: float = 0.0
    masked_copy_fraction: float = 0.0
    masked_copy_visible: bool = False
    set_shape: SetShape = "proportional"
    test_targets: tuple[int, int] = (1, 4)
    sparsest_share: float = 0.0
    distill_from: str | None = None
    distill_guidance_scale: float | None = None
    init_from: str | None = None

    def __post_init__(self) -> None:
        where = "[train]"
        if self.init_from is not None and self.distill_from is not None:
            raise UsageError(
                "init_from and distill_from exclude each other: a student starts from its teacher", where
            )
        check_choice(self.set_shape, SetShape, "set_shape", where)
        targets = tuple(int(t) for t in self.test_targets)
        if len(targets) != 2 or not 1 <= targets[0] <= targets[1]:
            raise UsageError(
                f"test_targets must be [lo, hi] with 1 <= lo <= hi, got {list(self.test_targets)}", where
            )
        object.__setattr__(self, "test_targets", targets)
        if not 0.0 <= self.sparsest_share < 1.0:
            raise UsageError(f"sparsest_share must be in [0, 1), got {self.sparsest_share}", where)
        if self.distill_guidance_scale is not None:
            check_guidance_scale(self.distill_guidance_scale, where)
        if not 0.0 <= self.identity_fraction < 1.0:
            raise UsageError(f"identity_fraction must be in [0, 1), got {self.identity_fraction}", where)
        if not 0.0 <= self.masked_copy_fraction < 1.0:
            raise UsageError(
                f"masked_copy_fraction must be in [0, 1), got {self.masked_copy_fraction}", where
            )
        if self.steps < 0 or self.gradient_accumulation < 1:
            raise UsageError("steps must be >= 0 and gradient_accumulation >= 1", where)
        if not 2 <= self.min_views <= self.max_views:
            raise UsageError(
                f"need 2 <= min_views <= max_views, got {self.min_views}, {self.max_views}", where
            )
        check_choice(self.mixed_precision, MixedPrecision, "mixed_precision", where, quoted=False)
        check_choice(self.lpips_net, LpipsNet, "lpips_net", where)
        weights = (self.latent_weight, self.l2_weight, self.ssim_weight, self.lpips_weight)
        if min(weights) < 0 or sum(weights) == 0:
            raise UsageError("loss weights must be >= 0 and not all zero", where)
        object.__setattr__(self, "adam_betas", tuple(float(b) for b in self.adam_betas))

    @property
    def reconstruction_weight(self) -> float:
        return self.l2_weight + self.ssim_weight + self.lpips_weight

    def to_dict(self) -> dict[str, Any]:
        return jsonable(asdict(self))


@dataclass(frozen=True)
class Config:
    """A model config and a training config, as read from one TOML file."""

    model: ModelConfig = field(default_factory=ModelConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    source: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"format": CONFIG_FORMAT, "model": self.model.to_dict(), "train": self.train.to_dict()}

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, sort_keys=True)


def check_choice(value: Any, choices: Any, name: str, where: str, *, quoted: bool = True) -> None:
    """Refuse ``value`` unless it is one of the ``Literal`` type ``choices``' values: ``<name> must be 'a' or 'b',
    got 'c'`` (``a, b or c`` when not ``quoted``)."""
    allowed = get_args(choices)
    if value not in allowed:
        words = [repr(choice) if quoted else str(choice) for choice in allowed]
        spelled = f"{', '.join(words[:-1])} or {words[-1]}"
        raise UsageError(f"{name} must be {spelled}, got {value!r}", where)


def check_guidance_scale(value: Any, where: str) -> float:
    """``value`` as a geometry CFG scale (a finite number > 0; 1 = conditional only), else UsageError."""
    try:
        scale = float(value)
    except (TypeError, ValueError):
        scale = math.nan
    if isinstance(value, bool) or not (math.isfinite(scale) and scale > 0):
        raise UsageError(f"guidance_scale must be a finite number > 0, got {value!r}", where)
    return scale


def config_from_dict(data: Mapping[str, Any], source: str = "") -> Config:
    """Build a :class:`Config` from ``{"model": {...}, "train": {...}}`` (TOML layout or saved JSON)."""
    unknown = set(data) - {"model", "train", "format"}
    if unknown:
        raise UsageError(f"unknown top-level tables {sorted(unknown)} (expected [model], [train])", source)
    model = model_config_from_dict(data.get("model", {}))
    train = _build(TrainConfig, data.get("train", {}), "[train]")
    return Config(model=model, train=train, source=source)


def model_config_from_dict(data: Mapping[str, Any]) -> ModelConfig:
    """Resolve ``preset`` and key-wise ``unet``/``vae`` overrides into a :class:`ModelConfig`."""
    data = dict(data)
    preset_name = data.get("preset", "sd-turbo")
    if preset_name not in PRESETS:
        raise UsageError(f"unknown preset {preset_name!r}; known: {', '.join(PRESETS)}", "[model]")
    preset = copy.deepcopy(PRESETS[preset_name])
    if data.get("autoencoder") and not _complete_vae(data.get("vae", {})):
        autoencoder = read_autoencoder_config(str(data["autoencoder"]))
        preset["vae"] = {**preset["vae"], **autoencoder}
        channels = int(autoencoder["latent_channels"])
        preset["unet"] = {**preset["unet"], "in_channels": channels, "out_channels": channels}
    for part in ("unet", "vae"):
        overrides = data.get(part, {})
        if not isinstance(overrides, Mapping):
            raise UsageError(f"[model.{part}] must be a table", "[model]")
        base = copy.deepcopy(preset[part])
        base.update(overrides)
        data[part] = base
    data.setdefault("geometry_channels", list(preset["geometry_channels"]))
    data.setdefault("scheduler", dict(SD_TURBO_SCHEDULE))
    return _build(ModelConfig, data, "[model]")


def _complete_vae(table: Any) -> bool:
    """A saved (checkpoint) config carries the whole VAE table, scale included; a TOML override does not."""
    return isinstance(table, Mapping) and {"latent_channels", "scaling_factor", "block_out_channels"} <= set(
        table
    )


def with_overrides(config: Config, **train_overrides: Any) -> Config:
    """A copy of ``config`` with some training fields replaced (``None`` values are ignored)."""
    updates = {k: v for k, v in train_overrides.items() if v is not None}
    return replace(config, train=replace(config.train, **updates)) if updates else config


def _build(cls: type, data: Mapping[str, Any], where: str) -> Any:
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise UsageError(f"unknown keys {unknown} in {where}; known: {', '.join(sorted(names))}", where)
    try:
        return cls(**dict(data))
    except TypeError as error:
        raise UsageError(f"invalid {where}: {error}", where) from error
