"""Pieces that let a from-scratch SetDiff use its set: the toolkit's tiny autoencoder, the identity-at-
initialisation output, identity and masked-copy training samples and the C-map distance attention bias."""

from __future__ import annotations

import json
import math
import random
from pathlib import Path

import pytest
import torch

from setdiff_bench.cli.main import main
from setdiff_bench.models.setdiff.autoencoder import load_autoencoder, read_autoencoder_config
from setdiff_bench.models.setdiff.config import model_config_from_dict
from setdiff_bench.models.setdiff.files import AUTOENCODER_WEIGHTS_FILE, CONFIG_FILE, MANIFEST_FILE
from setdiff_bench.models.setdiff.inference import enhance_packet
from setdiff_bench.models.setdiff.inputs import (
    HOLE_AREA,
    HOLE_VALUE,
    cut_holes,
    surface_points,
    training_set,
)
from setdiff_bench.models.setdiff.model import SetDiffModel
from setdiff_bench.models.setdiff.set_mixer import (
    BIAS_DISTANCE_CAP,
    BIAS_PARAMETER,
    distance_bias,
    token_grid,
)
from tests.models.setdiff_fixtures import (
    make_packet,
    make_sample,
    residual_model,
    tiny_config_toml,
    train_argv,
    write_store,
)


@pytest.mark.parametrize(
    "bias, layers", [("none", "all"), ("cmap_distance", "all"), ("cmap_distance", "lowest")]
)
def test_untrained_residual_model_returns_the_render(bias: str, layers: str) -> None:
    """Identity at initialisation: to the last 8-bit level, with geometry CFG on and the set mixer active."""
    packet = make_packet(3, 2, size=(32, 48))
    output = enhance_packet(residual_model(attention_bias=bias, attention_bias_layers=layers), packet)
    renders = packet.targets.images.float()
    assert (output * 255).round().equal((renders * 255).round())
    assert float((output - renders).abs().max()) < 0.5 / 255


def test_direct_model_does_not_return_the_render() -> None:
    """The paper's parameterisation has to learn the identity (the contrast the switch exists for)."""
    packet = make_packet(3, 2)
    output = enhance_packet(residual_model(output_mode="direct"), packet)
    assert float((output - packet.targets.images).abs().mean()) > 0.05


def test_residual_model_learns_a_correction() -> None:
    """The zero-initialised heads still receive gradients, so the output can move off the render."""
    model = residual_model().train()
    drawn = training_set(
        make_sample(2, 2), random.Random(0), min_views=4, max_views=4, use_geometry=True, cmap_clip=10.0
    )
    prediction = model(drawn.batch, geometry_keep=torch.ones(1), decode_index=torch.tensor([0, 1]))
    (prediction.decoded - drawn.target_gt[0]).square().mean().backward()
    assert float(model.unet.conv_out.weight.grad.abs().sum()) > 0


def test_identity_samples_feed_ground_truth_as_input() -> None:
    sample = make_sample(2, 3)
    rng_state = 7
    always = training_set(
        sample,
        random.Random(rng_state),
        min_views=5,
        max_views=5,
        use_geometry=True,
        cmap_clip=10.0,
        identity_probability=0.999999,
    )
    never = training_set(
        sample, random.Random(rng_state), min_views=5, max_views=5, use_geometry=True, cmap_clip=10.0
    )
    n = always.batch.num_references
    assert torch.equal(always.batch.images[0, n:], always.target_gt[0])
    assert torch.equal(always.batch.images[0, :n], never.batch.images[0, :n])
    assert not torch.equal(never.batch.images[0, n:], never.target_gt[0])


def test_cut_holes_fills_one_rectangle_per_view_around_a_surface_pixel() -> None:
    """A 40x60 view whose only surface pixel is (30, 50): the hole is a grey rectangle containing it."""
    images = torch.zeros(2, 3, 40, 60)
    alphas = torch.zeros(2, 1, 40, 60)
    alphas[:, :, 30, 50] = 1.0
    out = cut_holes(images, alphas, random.Random(3))
    assert torch.equal(images, torch.zeros(2, 3, 40, 60))  # the input is not modified
    for view in range(2):
        hole = out[view, 0] == HOLE_VALUE
        rows, cols = torch.nonzero(hole, as_tuple=True)
        top, bottom, left, right = int(rows.min()), int(rows.max()), int(cols.min()), int(cols.max())
        assert int(hole.sum()) == (bottom - top + 1) * (right - left + 1)  # a full rectangle
        assert top <= 30 <= bottom and left <= 50 <= right
        area = (bottom - top + 1) * (right - left + 1) / (40 * 60)
        assert 0.5 * HOLE_AREA[0] <= area <= 1.5 * HOLE_AREA[1]  # rounding and the border clip
        assert torch.equal(out[view, :, ~hole], images[view, :, ~hole])
        assert torch.equal(out[view, 1:][:, hole], out[view, 0][hole].expand(2, -1))


def test_masked_copy_samples_cut_the_target_renders_only() -> None:
    sample = make_sample(2, 3)
    kwargs = {"min_views": 5, "max_views": 5, "use_geometry": True, "cmap_clip": 10.0}
    masked = training_set(sample, random.Random(7), masked_copy_probability=0.999999, **kwargs)
    plain = training_set(sample, random.Random(7), **kwargs)
    n = masked.batch.num_references
    assert torch.equal(masked.batch.images[0, :n], plain.batch.images[0, :n])
    assert torch.equal(masked.batch.geometry, plain.batch.geometry)
    assert torch.equal(masked.target_gt, plain.target_gt)
    changed = (masked.batch.images[0, n:] != plain.batch.images[0, n:]).any(dim=1)  # (M, H, W)
    assert all(bool(changed[view].any()) for view in range(changed.shape[0]))
    assert torch.all(masked.batch.images[0, n:].permute(1, 0, 2, 3)[:, changed] == HOLE_VALUE)


def test_distance_bias_by_hand() -> None:
    """Three tokens: two 0.5 apart, one without a surface point."""
    points = torch.tensor([[[0.0, 0.0, 0.0], [0.0, 0.3, 0.4], [9.0, 9.0, 9.0]]])
    valid = torch.tensor([[True, True, False]])
    bias = distance_bias(points, valid, torch.tensor(2.0))[0, 0]
    cap = BIAS_DISTANCE_CAP
    expected = torch.tensor([[0.0, -0.5, -2 * cap], [-0.5, 0.0, -2 * cap], [-2 * cap, -2 * cap, -2 * cap]])
    torch.testing.assert_close(bias, expected)


def test_token_grid_follows_the_unet_downsamplers() -> None:
    assert token_grid(18, 32, 18 * 32) == (18, 32)
    assert token_grid(18, 32, 9 * 16) == (9, 16)
    assert token_grid(9, 16, 5 * 8) == (5, 8)  # ⌈9/2⌉ = 5
    with pytest.raises(RuntimeError):
        token_grid(18, 32, 100)


def test_attention_bias_equals_explicit_attention() -> None:
    """The set mixer with the bias equals softmax(QKᵀ/√d − s·d²)·V written out by hand."""
    model = residual_model(attention_bias="cmap_distance")
    name = model.mixed_attention[0].removesuffix(".processor")
    attn = dict(model.unet.named_modules())[name]
    processor = attn.processor
    views, tokens, channels = 2, 16, attn.to_q.in_features
    generator = torch.Generator().manual_seed(0)
    hidden = torch.randn(views, tokens, channels, generator=generator)
    cells = torch.cat([torch.randn(views, 3, 4, 4, generator=generator), torch.ones(views, 1, 4, 4)], dim=1)
    cells[1, :, 0, 0] = 0.0  # one cell without a surface point
    with torch.no_grad():
        output = processor(attn, hidden, num_views=views, token_points=cells)
        q, k, v = attn.to_q(hidden), attn.to_k(hidden), attn.to_v(hidden)
        heads = attn.heads
        d = q.shape[-1] // heads
        split = lambda x: x.reshape(1, views * tokens, heads, d).transpose(1, 2)  # noqa: E731
        xyz = cells[:, :3].flatten(2).transpose(1, 2).reshape(1, -1, 3)
        ok = cells[:, 3].flatten(1).reshape(1, -1) > 0.5
        squared = ((xyz[:, :, None] - xyz[:, None]) ** 2).sum(-1).clamp(max=BIAS_DISTANCE_CAP)
        squared[~(ok[:, :, None] & ok[:, None, :])] = BIAS_DISTANCE_CAP
        scale = math.exp(float(attn.set_bias_log_scale))
        logits = split(q) @ split(k).transpose(-1, -2) / math.sqrt(d) - scale * squared[:, None]
        mixed = (logits.softmax(-1) @ split(v)).transpose(1, 2).reshape(views, tokens, heads * d)
        expected = attn.to_out[1](attn.to_out[0](mixed)) / attn.rescale_output_factor
    torch.testing.assert_close(output, expected, atol=1e-5, rtol=1e-4)


#: A three-level variant of the tiny UNet (set mixers at two resolutions below the top), to check that
#: "lowest" follows the UNet's depth rather than the tiny preset's layout.
THREE_LEVEL_UNET = {
    "down_block_types": ["CrossAttnDownBlock2D", "CrossAttnDownBlock2D", "DownBlock2D"],
    "up_block_types": ["UpBlock2D", "CrossAttnUpBlock2D", "CrossAttnUpBlock2D"],
    "block_out_channels": [32, 64, 64],
    "attention_head_dim": [2, 4, 4],
}


@pytest.mark.parametrize("unet", [{}, THREE_LEVEL_UNET], ids=["tiny", "three_levels"])
def test_lowest_bias_layers_are_those_with_fewest_tokens(unet: dict) -> None:
    """`attention_bias_layers = "lowest"` puts the bias parameter on exactly the set-mixing layers that see
    the fewest tokens in a real forward pass (counted by wrapping each processor), and on no other."""
    model = residual_model(attention_bias="cmap_distance", attention_bias_layers="lowest", unet=unet)
    modules = dict(model.unet.named_modules())
    tokens: dict[str, int] = {}

    class Counting:
        """Records the tokens per view a layer sees, then attends as before (diffusers passes the set
        kwargs only to processors whose signature names them)."""

        def __init__(self, name: str, inner: object) -> None:
            self.name, self.inner = name, inner

        def __call__(
            self,
            attn,
            hidden_states,
            encoder_hidden_states=None,
            attention_mask=None,
            temb=None,
            num_views=None,
            token_points=None,
        ):
            tokens[self.name] = int(hidden_states.shape[1])
            return self.inner(attn, hidden_states, num_views=num_views, token_points=token_points)

    for name in model.mixed_attention:
        attn = modules[name.removesuffix(".processor")]
        attn.processor = Counting(name, attn.processor)
    enhance_packet(model, make_packet(2, 1, size=(64, 96)))
    fewest = min(tokens.values())
    assert len(set(tokens.values())) > 1
    for name in model.mixed_attention:
        has_bias = hasattr(modules[name.removesuffix(".processor")], BIAS_PARAMETER)
        assert has_bias == (tokens[name] == fewest), (name, tokens)


def test_layers_without_the_bias_ignore_the_points() -> None:
    """In a "lowest" model the other set-mixing layers attend exactly as the plain mixer does."""
    model = residual_model(attention_bias="cmap_distance", attention_bias_layers="lowest")
    modules = dict(model.unet.named_modules())
    views, tokens = 2, 16
    generator = torch.Generator().manual_seed(1)
    cells = torch.cat([torch.randn(views, 3, 4, 4, generator=generator), torch.ones(views, 1, 4, 4)], dim=1)
    changed = {}
    for name in model.mixed_attention:
        attn = modules[name.removesuffix(".processor")]
        hidden = torch.randn(views, tokens, attn.to_q.in_features, generator=generator)
        with torch.no_grad():
            plain = attn.processor(attn, hidden, num_views=views)
            with_points = attn.processor(attn, hidden, num_views=views, token_points=cells)
        changed[name] = not torch.equal(plain, with_points)
    assert changed == {name: name.startswith("mid_block") for name in model.mixed_attention}


def test_surface_points_divide_by_alpha_where_valid() -> None:
    packet = make_packet(1, 1)
    points = surface_points(packet)
    alphas = torch.cat([packet.references.alphas, packet.targets.alphas])
    cmaps = torch.cat([packet.references.cmaps, packet.targets.cmaps])
    valid = alphas > 0.5
    assert torch.equal(points[:, 3:] > 0, valid)
    torch.testing.assert_close(
        points[:, :3][valid.expand(-1, 3, -1, -1)], (cmaps / alphas)[valid.expand(-1, 3, -1, -1)]
    )


def test_train_autoencoder_and_build_a_model_on_it(tmp_path: Path) -> None:
    """`train autoencoder` writes weights, config and manifest; a config naming it builds a model whose
    VAE has its architecture, scale and weights, and a frozen encoder."""
    write_store(tmp_path / "packets")
    out = tmp_path / "ae"
    assert (
        main(
            [
                "train",
                "autoencoder",
                "--packets",
                str(tmp_path / "packets"),
                "--out",
                str(out),
                "--steps",
                "3",
                "--batch-size",
                "2",
                "--crop",
                "16",
                "--latent-channels",
                "6",
                "--base-channels",
                "8",
                "--device",
                "cpu",
                "--no-progress",
            ]
        )
        == 0
    )
    assert {p.name for p in out.iterdir()} == {CONFIG_FILE, AUTOENCODER_WEIGHTS_FILE, MANIFEST_FILE}
    manifest = json.loads((out / MANIFEST_FILE).read_text())
    assert (
        manifest["settings"]["steps"] == 3 and manifest["train_frames"] == 6 and manifest["test_frames"] == 6
    )
    assert manifest["train_scenes"] == ["s0"] and manifest["test_scenes"] == ["s1"]
    assert len(manifest["data_sha256"]) == 64 and math.isfinite(manifest["reconstruction_test"]["psnr"])
    config = read_autoencoder_config(out)
    assert config["latent_channels"] == 6 and config["scaling_factor"] == manifest["scaling_factor"] > 0
    assert config["block_out_channels"] == [8, 16, 16, 16] and manifest["device"] == "cpu"
    assert manifest["settings"]["base_channels"] == 8
    model = SetDiffModel(
        model_config_from_dict({"preset": "tiny", "autoencoder": str(out), "vae_decoder": "full"})
    )
    assert model.config.unet["in_channels"] == 6 and model.codec.scaling_factor == config["scaling_factor"]
    assert list(model.codec.vae.config.block_out_channels) == [8, 16, 16, 16]
    from safetensors.torch import load_file

    saved = load_file(str(out / AUTOENCODER_WEIGHTS_FILE))
    state = model.codec.vae.state_dict()
    assert all(torch.equal(state[k], v) for k, v in saved.items())
    alone = load_autoencoder(out)  # the folder on its own, as benchmarks/autoencoder_sweep.py scores it
    assert not alone.training and all(torch.equal(alone.state_dict()[k], v) for k, v in saved.items())
    assert not any(p.requires_grad for p in model.codec.vae.encoder.parameters())


def test_autoencoder_width_not_a_multiple_of_8_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_store(tmp_path / "packets")
    argv = ["train", "autoencoder", "--packets", str(tmp_path / "packets"), "--out", str(tmp_path / "ae")]
    code = main([*argv, "--base-channels", "12", "--steps", "1", "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "base channels a multiple of 8" in err[0]
    assert not (tmp_path / "ae").exists()


def test_missing_autoencoder_is_one_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    config = tmp_path / "c.toml"
    config.write_text(tiny_config_toml(model={"preset": "tiny", "autoencoder": "no_such_autoencoder"}))
    write_store(tmp_path / "packets")
    code = main(train_argv(config, tmp_path / "packets", tmp_path / "run", "--no-progress"))
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "no_such_autoencoder" in err[0] and "autoencoder" in err[0]
    assert not (tmp_path / "run").exists()
