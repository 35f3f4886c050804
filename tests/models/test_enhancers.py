"""``--method setdiff`` / ``--method difix`` through the enhancer registry."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import torch

from setdiff_bench.enhancers.base import Enhancer, available_methods, create_enhancer
from setdiff_bench.errors import CheckpointError, UsageError
from setdiff_bench.models.setdiff.checkpoint import save_checkpoint
from setdiff_bench.models.setdiff.inference import enhance_packet
from setdiff_bench.models.setdiff.model import SetDiffModel
from tests.models.setdiff_fixtures import DIFIX, make_packet, tiny_config


def saved(tmp_path: Path, **overrides: object) -> tuple[Path, SetDiffModel]:
    config = tiny_config(**overrides)
    torch.manual_seed(0)
    model = SetDiffModel(config.model).eval()
    return save_checkpoint(tmp_path / "ckpt", model, config), model


def test_registered_as_builtins() -> None:
    methods = available_methods()
    for name in ("setdiff", "difix"):
        assert methods[name].needs_weights
        assert methods[name].factory.startswith(f"setdiff_bench.enhancers.{name}:")


def test_setdiff_enhancer(tmp_path: Path) -> None:
    folder, model = saved(tmp_path)
    enhancer = create_enhancer("setdiff", checkpoint=str(folder), device="cpu")
    assert isinstance(enhancer, Enhancer) and enhancer.name == "setdiff"
    packet = make_packet(2, 3)
    output = enhancer.enhance(packet)
    assert output.shape == (3, 3, 32, 32) and output.dtype == torch.float32
    assert torch.equal(output, enhance_packet(model, packet))
    assert enhancer.options["guidance_scale"] == 2.0
    assert (
        create_enhancer("setdiff", checkpoint=str(folder), guidance_scale=1.5).options["guidance_scale"]
        == 1.5
    )


def test_difix_enhancer(tmp_path: Path) -> None:
    folder, model = saved(tmp_path, **DIFIX)
    enhancer = create_enhancer("difix", checkpoint=str(folder), device="cpu")
    packet = make_packet(3, 2)
    output = enhancer.enhance(packet)
    assert output.shape == (2, 3, 32, 32)
    # default: each target with its nearest-pose reference (Difix3D's rule), one set per target
    from setdiff_bench.enhancers.difix import nearest_pose_assignments

    choice = nearest_pose_assignments(packet.references.cameras, packet.targets.cameras)
    for target, reference in enumerate(choice):
        single = dataclasses.replace(
            packet, references=packet.references.subset([reference]), targets=packet.targets.subset([target])
        )
        assert torch.allclose(output[target : target + 1], enhance_packet(model, single), atol=1e-5)
    eq2 = create_enhancer("difix", checkpoint=str(folder), device="cpu", references="eq2")
    assert torch.equal(eq2.enhance(packet), enhance_packet(model, packet))  # the packet's first reference


def test_method_and_checkpoint_must_match(tmp_path: Path) -> None:
    folder, _ = saved(tmp_path)
    with pytest.raises(CheckpointError, match="trained as method 'setdiff'"):
        create_enhancer("difix", checkpoint=str(folder))


def test_checkpoint_is_required() -> None:
    with pytest.raises(UsageError, match=r"^checkpoint: method 'setdiff' needs a trained model") as caught:
        create_enhancer("setdiff")
    assert "--checkpoint" not in str(caught.value)  # a Python caller passes checkpoint=, not a flag
    with pytest.raises(CheckpointError, match="not found"):
        create_enhancer("setdiff", checkpoint="/nonexistent/ckpt")
