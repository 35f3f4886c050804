"""SetDiffModel on the tiny configuration: one-step maths, set behaviour, geometry CFG, input checks."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from setdiff_bench.errors import PacketError
from setdiff_bench.geometry import renormalize
from setdiff_bench.models.setdiff.config import model_config_from_dict
from setdiff_bench.models.setdiff.inference import enhance_packet, set_packets
from setdiff_bench.models.setdiff.inputs import SetBatch, view_tensors
from setdiff_bench.models.setdiff.model import SetDiffModel
from tests.models.setdiff_fixtures import DIFIX, make_packet

# docs/model.md, "SD-Turbo schedule at t = 199": SD-Turbo scaled_linear schedule at t = 199.
ALPHA_BAR_199 = 0.7552384
SQRT_ALPHA_BAR_199 = 0.8690445
SQRT_ONE_MINUS_ALPHA_BAR_199 = 0.4947339


def tiny_model(**overrides: object) -> SetDiffModel:
    torch.manual_seed(0)
    model = SetDiffModel(model_config_from_dict({"preset": "tiny", **overrides}))
    return model.eval()


def activate_geometry(model: SetDiffModel) -> None:
    """Give Ψ's zero-initialised output conv non-zero weights so geometry changes the result."""
    assert model.geometry_encoder is not None
    generator = torch.Generator().manual_seed(5)
    with torch.no_grad():
        out = model.geometry_encoder.out
        out.weight.copy_(0.05 * torch.randn(out.weight.shape, generator=generator))
        out.bias.copy_(0.05 * torch.randn(out.bias.shape, generator=generator))


@pytest.fixture(scope="module")
def model() -> SetDiffModel:
    m = tiny_model(skip_connections=True)
    activate_geometry(m)
    return m


def test_alpha_bar_matches_reference_table() -> None:
    config = model_config_from_dict({"preset": "tiny"})
    assert config.alpha_bar == pytest.approx(ALPHA_BAR_199, abs=1e-7)
    assert model_config_from_dict({"preset": "tiny", "timestep": 999}).alpha_bar == pytest.approx(
        0.0046601, abs=1e-7
    )


@pytest.mark.parametrize("prediction", ["v_prediction", "epsilon"])
def test_x0_formulas(prediction: str) -> None:
    model = tiny_model(prediction=prediction, use_geometry=False)
    z, out = torch.randn(2, 4, 3, 3, dtype=torch.float64), torch.randn(2, 4, 3, 3, dtype=torch.float64)
    if prediction == "v_prediction":
        expected = SQRT_ALPHA_BAR_199 * z - SQRT_ONE_MINUS_ALPHA_BAR_199 * out
    else:
        expected = (z - SQRT_ONE_MINUS_ALPHA_BAR_199 * out) / SQRT_ALPHA_BAR_199
    torch.testing.assert_close(model.to_x0(z, out), expected, atol=1e-6, rtol=0)
    # v and ε parameterise the same x0: ε = √(1−ᾱ)·z + √ᾱ·v (docs/model.md, "One-step formulation")
    if prediction == "epsilon":
        v = out
        eps = math.sqrt(1 - ALPHA_BAR_199) * z + math.sqrt(ALPHA_BAR_199) * v
        x0_v = math.sqrt(ALPHA_BAR_199) * z - math.sqrt(1 - ALPHA_BAR_199) * v
        torch.testing.assert_close(model.to_x0(z, eps), x0_v, atol=1e-6, rtol=0)


def test_codec_walk_matches_diffusers() -> None:
    model = tiny_model(vae_decoder="frozen")
    images = torch.rand(2, 3, 32, 32)
    vae = model.codec.vae
    with torch.no_grad():
        reference = vae.encode(images * 2 - 1).latent_dist.mean * vae.config.scaling_factor
        latents = model.encode(images).latents
        torch.testing.assert_close(latents, reference, atol=1e-6, rtol=1e-5)
        decoded_reference = (vae.decode(latents / vae.config.scaling_factor).sample.clamp(-1, 1) + 1) / 2
        torch.testing.assert_close(model.decode(latents), decoded_reference, atol=1e-6, rtol=1e-5)


def test_untrained_geometry_encoder_adds_nothing() -> None:
    model = tiny_model()
    packet = make_packet(2, 2)
    images, geometry, n = view_tensors(packet, use_geometry=True, cmap_clip=10.0)
    batch = SetBatch(images[None], geometry[None], n)
    without = SetBatch(images[None], None, n)
    assert torch.equal(model.enhance(batch, guidance_scale=1.0), model.enhance(without))
    torch.testing.assert_close(
        model.enhance(batch, guidance_scale=2.0), model.enhance(without), atol=1e-5, rtol=0
    )


def test_permuting_views_permutes_outputs(model: SetDiffModel) -> None:
    packet = make_packet(3, 4)
    reference = enhance_packet(model, packet)
    ref_order, target_order = [2, 0, 1], [3, 1, 0, 2]
    permuted = replace(
        make_packet(3, 4),
        references=packet.references.subset(ref_order),
        targets=packet.targets.subset(target_order),
    )
    output = enhance_packet(model, permuted)
    assert output.shape == (4, 3, 32, 32)
    torch.testing.assert_close(output, reference[target_order], atol=1e-5, rtol=0)


def test_references_change_the_targets(model: SetDiffModel) -> None:
    """The set mixer really mixes: other references give other target outputs."""
    a, b = make_packet(2, 2, seed=0), make_packet(2, 2, seed=0)
    b = replace(b, references=make_packet(2, 2, seed=1).references)
    assert (enhance_packet(model, a) - enhance_packet(model, b)).abs().max() > 1e-4


@pytest.mark.parametrize(("refs", "targets"), [(1, 1), (3, 6), (0, 2)])
def test_set_sizes_run(model: SetDiffModel, refs: int, targets: int) -> None:
    output = enhance_packet(model, make_packet(refs, targets))
    assert output.shape == (targets, 3, 32, 32)
    assert output.dtype == torch.float32
    assert float(output.min()) >= 0.0 and float(output.max()) <= 1.0


def test_geometry_dropout_removes_geometry(model: SetDiffModel) -> None:
    packet = make_packet(2, 2)
    images, geometry, n = view_tensors(packet, use_geometry=True, cmap_clip=10.0)
    other_geometry = torch.randn_like(geometry)
    batch = SetBatch(images[None], geometry[None], n)
    with torch.no_grad():
        dropped = model(batch, geometry_keep=torch.zeros(1)).target_x0
        dropped_other = model(
            SetBatch(images[None], other_geometry[None], n), geometry_keep=torch.zeros(1)
        ).target_x0
        no_geometry = model(SetBatch(images[None], None, n)).target_x0
        kept = model(batch, geometry_keep=torch.ones(1)).target_x0
    assert torch.equal(dropped, no_geometry)
    assert torch.equal(dropped, dropped_other)
    assert (kept - dropped).abs().max() > 1e-4


def test_guidance_scale(model: SetDiffModel) -> None:
    packet = make_packet(2, 3)
    images, geometry, n = view_tensors(packet, use_geometry=True, cmap_clip=10.0)
    flat_images, flat_geometry = images, geometry
    with torch.no_grad():
        latents = model.encode(flat_images).latents
        x0_cond = model.predict_x0(latents, flat_geometry, 5, guidance_scale=1.0)
        x0_uncond = model.predict_x0(latents, None, 5)
        x0_guided = model.predict_x0(latents, flat_geometry, 5, guidance_scale=2.0)
    # CFG: x0 = x0_u + s (x0_c − x0_u), computed here from two separate passes
    torch.testing.assert_close(x0_guided, x0_uncond + 2.0 * (x0_cond - x0_uncond), atol=1e-5, rtol=0)
    assert (x0_guided - x0_cond).abs().max() > 1e-4
    batch = SetBatch(images[None], geometry[None], n)
    assert (
        model.enhance(batch, guidance_scale=2.0) - model.enhance(batch, guidance_scale=1.0)
    ).abs().max() > 1e-4


def test_batched_and_sequential_cfg_agree(model: SetDiffModel) -> None:
    packet = make_packet(2, 2)
    images, geometry, n = view_tensors(packet, use_geometry=True, cmap_clip=10.0)
    batch = SetBatch(images[None], geometry[None], n)
    batched = model.enhance(batch)
    sequential_model = tiny_model(skip_connections=True, cfg_batched=False)
    sequential_model.load_state_dict(model.state_dict())
    torch.testing.assert_close(sequential_model.enhance(batch), batched, atol=1e-5, rtol=0)


def test_sets_in_a_batch_do_not_mix(model: SetDiffModel) -> None:
    a, b = make_packet(1, 2, seed=3), make_packet(1, 2, seed=4)
    ia, ga, n = view_tensors(a, use_geometry=True, cmap_clip=10.0)
    ib, gb, _ = view_tensors(b, use_geometry=True, cmap_clip=10.0)
    both = model.enhance(SetBatch(torch.stack([ia, ib]), torch.stack([ga, gb]), n))
    torch.testing.assert_close(both[1], model.enhance(SetBatch(ib[None], gb[None], n))[0], atol=1e-5, rtol=0)


def test_difix_pairs_first_reference_with_each_target() -> None:
    model = tiny_model(**DIFIX)
    packet = make_packet(3, 3)
    output = enhance_packet(model, packet)
    for target in range(3):
        single = replace(
            make_packet(3, 3),
            references=packet.references.subset([0]),
            targets=packet.targets.subset([target]),
        )
        torch.testing.assert_close(output[target], enhance_packet(model, single)[0], atol=1e-5, rtol=0)
    torch.testing.assert_close(enhance_packet(model, packet, sets_per_call=1), output, atol=1e-5, rtol=0)


def test_rejects_size_not_divisible_by_8(model: SetDiffModel) -> None:
    with pytest.raises(PacketError, match="not divisible by 8"):
        enhance_packet(model, make_packet(1, 1, size=(36, 32)))


def test_rejects_packet_without_targets(model: SetDiffModel) -> None:
    with pytest.raises(PacketError, match="no target"):
        enhance_packet(model, make_packet(2, 0))


def test_gradient_checkpointing_keeps_gradients() -> None:
    """Recomputed blocks see the set size too (it travels in cross_attention_kwargs)."""
    packet = make_packet(2, 2)
    images, geometry, n = view_tensors(packet, use_geometry=True, cmap_clip=10.0)
    batch = SetBatch(images[None], geometry[None], n)
    gradients = []
    for checkpointing in (False, True):
        model = tiny_model(skip_connections=True)
        activate_geometry(model)
        model.train()
        if checkpointing:
            model.unet.enable_gradient_checkpointing()
        out = model(batch, geometry_keep=torch.ones(1), decode_index=torch.tensor([1]))
        (out.target_x0.square().mean() + out.decoded.mean()).backward()
        gradients.append({k: p.grad.clone() for k, p in model.named_parameters() if p.grad is not None})
    assert gradients[0].keys() == gradients[1].keys()
    for key, value in gradients[0].items():
        torch.testing.assert_close(gradients[1][key], value, atol=1e-6, rtol=1e-5, msg=key)


def test_inference_set_size_overrides_equal_explicit_subsets(model: SetDiffModel) -> None:
    """max_references = N keeps the first N references; targets_per_set = M enhances M targets per set,
    each subset re-normalised into its own first target's frame as training does."""
    packet = make_packet(3, 4)
    limited = enhance_packet(model, packet, max_references=1, targets_per_set=2)
    for chunk in ([0, 1], [2, 3]):
        explicit = replace(
            make_packet(3, 4), references=packet.references.subset([0]), targets=packet.targets.subset(chunk)
        )
        torch.testing.assert_close(
            limited[chunk], enhance_packet(model, renormalize(explicit)), atol=1e-5, rtol=0
        )
    assert (limited - enhance_packet(model, packet)).abs().max() > 1e-5


def camera_points(camera, points: np.ndarray) -> np.ndarray:
    """``(3, P)`` world points → camera coordinates."""
    w2c = np.asarray(camera.w2c, dtype=np.float64)
    return w2c[:3, :3] @ points + w2c[:3, 3:]


def project(camera, points: np.ndarray) -> np.ndarray:
    """``(3, P)`` world points → ``(2, P)`` pixels."""
    uv = np.asarray(camera.K, dtype=np.float64) @ camera_points(camera, points)
    return uv[:2] / uv[2:]


def test_inference_subsets_satisfy_the_training_normalisation() -> None:
    """Every proper subset: first target at the identity pose, largest camera-centre distance 1 (the
    packet invariant), C-maps moved by the same similarity; the whole packet is left as it is."""
    packet = make_packet(3, 4)
    whole = set_packets(packet, None, None, renormalise=True)
    assert len(whole) == 1 and whole[0][0] is packet
    for subset, chunk in set_packets(packet, 2, 2, renormalise=True):
        cameras = (*subset.references.cameras, *subset.targets.cameras)
        centres = np.stack([c.center for c in cameras])
        assert len(subset.references) == 2 and len(subset.targets) == len(chunk) == 2
        np.testing.assert_allclose(np.asarray(subset.targets.cameras[0].w2c), np.eye(4), atol=1e-5)
        distances = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
        assert distances.max() == pytest.approx(1.0, abs=1e-5)
        # a C-map point keeps its pixel: project the first target's C-map with its (new) camera
        first = subset.targets.cameras[0]
        cmap = subset.targets.cmaps[0].double().numpy().reshape(3, -1)
        original = packet.targets.cameras[chunk[0]]
        before = packet.targets.cmaps[chunk[0]].double().numpy().reshape(3, -1)
        valid = np.abs(camera_points(original, before)[2]) > 0.1
        np.testing.assert_allclose(
            project(first, cmap)[:, valid], project(original, before)[:, valid], atol=1e-3
        )
