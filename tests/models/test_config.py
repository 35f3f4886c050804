"""Configs: packaged TOML files, validation, and the analytic noise schedule against diffusers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from setdiff_bench.errors import UsageError
from setdiff_bench.models.setdiff.config import (
    ModelConfig,
    TrainConfig,
    check_guidance_scale,
    config_from_dict,
    model_config_from_dict,
)
from setdiff_bench.models.setdiff.config_io import load_config, packaged_configs
from setdiff_bench.models.setdiff.presets import SD_TURBO_SCHEDULE, alphas_cumprod


def test_packaged_configs_load() -> None:
    names = set(packaged_configs())
    assert {"tiny_setdiff", "tiny_difix", "sd_turbo_setdiff", "sd_turbo_difix"} <= names
    for name in names:
        config = load_config(name)
        assert config.model.method in name
        assert config.model.timestep == 199
    setdiff = load_config("sd_turbo_setdiff")
    assert setdiff.model.prediction == "v_prediction" and setdiff.model.geometry_dropout == 0.15
    assert setdiff.model.guidance_scale == 2.0 and setdiff.model.vae_lora_rank == 4
    assert list(setdiff.model.unet["attention_head_dim"]) == [5, 10, 20, 20]
    assert (setdiff.train.min_views, setdiff.train.max_views) == (8, 12)
    difix = load_config("sd_turbo_difix")
    assert difix.model.prediction == "epsilon" and not difix.model.use_geometry and not difix.model.uses_cfg


#: The A/B configs in benchmarks/configs/: the config each arm copies (a packaged name, or a file in that
#: folder) and the keys it changes.  tiny_setdiff_plain.toml is the tiny_setdiff recipe before it took the
#: lowest-layer bias and LPIPS x2; the older arms are A/Bs against it.
PLAIN = "tiny_setdiff_plain.toml"
BIAS_LOWEST = {("model", "attention_bias"): "cmap_distance", ("model", "attention_bias_layers"): "lowest"}
#: What a fine-tune of a shipped model changes in its recipe (500 steps at learning rate 1e-4).
FINE_TUNE = {
    ("train", "steps"): 500,
    ("train", "learning_rate"): 1e-4,
    ("train", "checkpoint_every"): 250,
    ("train", "validate_every"): 250,
}
AB_CONFIGS: dict[str, tuple[str, dict[tuple[str, str], object]]] = {
    PLAIN: (
        "tiny_setdiff",
        {
            ("model", "attention_bias"): "none",
            ("model", "attention_bias_layers"): "all",
            ("train", "lpips_weight"): 1.0,
        },
    ),
    "tiny_difix_lpips2.toml": ("tiny_difix", {("train", "lpips_weight"): 2.0}),
    "tiny_setdiff_cmap_bias.toml": (PLAIN, {("model", "attention_bias"): "cmap_distance"}),
    "tiny_setdiff_cmap_bias_lowest.toml": (PLAIN, BIAS_LOWEST),
    # the recipe the packaged tiny_setdiff took (the shipped model's manifest names this file)
    "tiny_setdiff_cmap_bias_lowest_lpips2.toml": ("tiny_setdiff", {}),
    "tiny_setdiff_lpips2.toml": (PLAIN, {("train", "lpips_weight"): 2.0}),
    "tiny_setdiff_masked_copy.toml": (PLAIN, {("train", "masked_copy_fraction"): 0.4}),
    # issue 55's speed options (benchmarks/speed_options.sh): fine-tunes with restricted level-0 attention
    **{
        f"{teacher}_{attention}0.toml": (
            "tiny_setdiff",
            {**FINE_TUNE, ("model", "set_attention"): [attention], ("train", "init_from"): teacher},
        )
        for teacher in ("tiny_setdiff", "tiny_setdiff_sparse")
        for attention in ("view", "knn")
    },
    **{
        f"{teacher}_finetune.toml": ("tiny_setdiff", {**FINE_TUNE, ("train", "init_from"): teacher})
        for teacher in ("tiny_setdiff", "tiny_setdiff_sparse")
    },
    # issue 52: the test-shaped sets recipe with kNN attention at the 576-token layers (bias vs kNN)
    "tiny_setdiff_sparse_sets_knn.toml": ("tiny_setdiff_sparse_sets", {("model", "set_attention"): ["knn"]}),
    "tiny_setdiff_student_view0.toml": ("tiny_setdiff_student", {("model", "set_attention"): ["view"]}),
    "tiny_setdiff_sparse_student_view0.toml": (
        "tiny_setdiff_sparse_student",
        {("model", "set_attention"): ["view"]},
    ),
}
AB_FOLDER = Path(__file__).parents[2] / "benchmarks" / "configs"


def test_every_ab_config_is_checked() -> None:
    assert sorted(p.name for p in AB_FOLDER.glob("*.toml")) == sorted(AB_CONFIGS)


@pytest.mark.parametrize("file_name", sorted(AB_CONFIGS))
def test_ab_configs_differ_from_the_config_they_copy_only_in_their_keys(file_name: str) -> None:
    """An A/B arm is only an A/B while its copy of another config stays in step with the original."""
    base_name, changes = AB_CONFIGS[file_name]
    arm = load_config(AB_FOLDER / file_name).to_dict()
    base = load_config(AB_FOLDER / base_name if base_name.endswith(".toml") else base_name).to_dict()
    for (table, key), value in changes.items():
        assert arm[table][key] == value != base[table][key]
        arm[table][key] = base[table][key]
    assert arm == base


def test_alphas_cumprod_matches_diffusers() -> None:
    from diffusers import DDPMScheduler

    scheduler = DDPMScheduler.from_config({**SD_TURBO_SCHEDULE, "clip_sample": False})
    ours = alphas_cumprod(**SD_TURBO_SCHEDULE)
    np.testing.assert_allclose(ours, scheduler.alphas_cumprod.numpy(), rtol=2e-6)


def test_overrides_and_errors(tmp_path: Path) -> None:
    config = config_from_dict(
        {"model": {"preset": "tiny", "unet": {"layers_per_block": 2}}, "train": {"steps": 7}}
    )
    assert config.model.unet["layers_per_block"] == 2 and config.model.unet["block_out_channels"] == [32, 64]
    assert config.train.steps == 7
    with pytest.raises(UsageError, match="unknown preset"):
        config_from_dict({"model": {"preset": "sdxl"}})
    with pytest.raises(UsageError, match="RGB-only"):
        config_from_dict({"model": {"preset": "tiny", "method": "difix"}})
    with pytest.raises(UsageError, match="min_views"):
        config_from_dict({"train": {"min_views": 9, "max_views": 8}})
    broken = tmp_path / "broken.toml"
    broken.write_text("[model\n")
    with pytest.raises(UsageError, match="cannot read config TOML"):
        load_config(broken)


def test_guidance_scale_must_be_a_finite_positive_number() -> None:
    assert check_guidance_scale(1, "x") == 1.0 and check_guidance_scale("1.5", "x") == 1.5
    for bad in (0, -1.0, float("nan"), float("inf"), True, "two", None):
        with pytest.raises(UsageError, match="guidance_scale must be a finite number > 0"):
            check_guidance_scale(bad, "x")
    with pytest.raises(UsageError, match="guidance_scale"):
        model_config_from_dict({**load_config("tiny_setdiff").model.to_dict(), "guidance_scale": 0.0})


def test_the_architecture_is_the_fields_marked_so() -> None:
    """A checkpoint's identity: these fields (declared with ARCHITECTURE metadata), not the inference knobs."""
    assert set(ModelConfig().architecture()) == {
        "method",
        "unet",
        "vae",
        "scheduler",
        "timestep",
        "prediction",
        "use_geometry",
        "geometry_inputs",
        "geometry_channels",
        "geometry_groups",
        "cmap_clip",
        "vae_decoder",
        "vae_lora_rank",
        "vae_lora_alpha",
        "skip_connections",
        "skip_gamma",
        "text_length",
        "output_mode",
        "attention_bias",
        "attention_bias_layers",
        "set_attention",
        "set_attention_neighbours",
    }
    knobs = ModelConfig(
        guidance_scale=1.0, cfg_batched=False, max_references=2, targets_per_set=1, preset="tiny"
    )
    assert knobs.architecture() == ModelConfig().architecture()


@pytest.mark.parametrize(
    ("table", "values", "message"),
    [
        ("model", {"vae_decoder": "half"}, "vae_decoder must be lora, full or frozen, got 'half'"),
        ("model", {"output_mode": "x"}, "output_mode must be 'direct' or 'residual', got 'x'"),
        ("train", {"mixed_precision": "fp8"}, "mixed_precision must be auto, no, bf16 or fp16, got 'fp8'"),
        ("train", {"lpips_net": "squeeze"}, "lpips_net must be 'vgg' or 'alex', got 'squeeze'"),
    ],
)
def test_choices_are_spelled_from_their_literal_types(table: str, values: dict, message: str) -> None:
    with pytest.raises(UsageError) as caught:
        ModelConfig(**values) if table == "model" else TrainConfig(**values)
    assert str(caught.value) == f"[{table}]: {message}"
