"""Issue 41: SetDiff and DiFix enhance packets of any size (reflect-pad to the multiple of 8, crop back).

References are independent of the code under test: ``numpy.pad`` for the padded pixels, a hand-written
pinhole projection for the padded cameras, and the model's own ``enhance_packet`` on a packet padded
here with ``numpy.pad`` for the enhancers' outputs.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.enhancers.base import create_enhancer
from setdiff_bench.enhancers.padding import crop, pad_camera, pad_images, pad_packet, padded_size, padding_for
from setdiff_bench.models.setdiff.checkpoint import save_checkpoint
from setdiff_bench.models.setdiff.inference import enhance_packet
from setdiff_bench.models.setdiff.model import SetDiffModel
from setdiff_bench.runtime.threads import torch_threads
from setdiff_bench.types import Packet, ViewSet
from tests.models.setdiff_fixtures import DIFIX, make_packet, tiny_config


@pytest.fixture(autouse=True)
def one_thread():
    with torch_threads(1):
        yield


@pytest.mark.parametrize(
    ("size", "expected", "sides"),
    [
        ((270, 480), (272, 480), (1, 1, 0, 0)),  # the ¼-size instant-ngp fox
        ((137, 251), (144, 256), (3, 4, 2, 3)),  # 7 rows: 3 above, 4 below; 5 columns: 2 left, 3 right
        ((32, 48), (32, 48), (0, 0, 0, 0)),
        ((3, 1), (8, 8), (2, 3, 3, 4)),
    ],
)
def test_padding_by_hand(size, expected, sides) -> None:
    padding = padding_for(*size, 8)
    assert (padding.top, padding.bottom, padding.left, padding.right) == sides
    assert padded_size(*size, 8) == expected
    with pytest.raises(ValueError):
        padding_for(0, 5, 8)


def _np_pad(array: np.ndarray, sides: tuple[int, int, int, int], mode: str) -> np.ndarray:
    top, bottom, left, right = sides
    return np.pad(array, ((0, 0), (0, 0), (top, bottom), (left, right)), mode=mode)


def test_reflect_padding_matches_numpy_and_crop_inverts_it() -> None:
    images = torch.rand(2, 3, 137, 251, generator=torch.Generator().manual_seed(0))
    padding = padding_for(137, 251, 8)
    padded = pad_images(images, padding)
    assert padded.shape == (2, 3, 144, 256)
    # numpy's "reflect" = torch's reflect (edge pixel not repeated)
    expected = _np_pad(images.numpy(), (3, 4, 2, 3), "reflect")
    assert np.array_equal(padded.numpy(), expected)
    assert torch.equal(crop(padded, padding), images)
    # an axis too short to reflect (1 column, 4 + 3 to add) is edge-replicated; the other still reflects
    narrow = torch.rand(1, 1, 5, 1, generator=torch.Generator().manual_seed(1))
    small = padding_for(5, 1, 8)
    out = pad_images(narrow, small)
    assert out.shape == (1, 1, 8, 8)
    reference = np.pad(narrow.numpy(), ((0, 0), (0, 0), (0, 0), (3, 4)), mode="edge")
    reference = np.pad(reference, ((0, 0), (0, 0), (1, 2), (0, 0)), mode="reflect")
    assert np.array_equal(out.numpy(), reference)


def test_padded_camera_projects_every_point_shifted_by_the_padding() -> None:
    K = np.array([[200.0, 0.0, 240.3], [0.0, 190.0, 135.7], [0.0, 0.0, 1.0]])
    angle = 0.3
    c2w = np.eye(4)
    c2w[:3, :3] = [[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]]
    c2w[:3, 3] = (1.0, -0.5, 2.0)
    camera = Camera.from_c2w(c2w, K, 480, 270)
    padding = padding_for(270, 480, 8)
    padded = pad_camera(camera, padding)
    assert (padded.width, padded.height) == (480, 272)
    points = np.random.default_rng(0).normal(size=(20, 3)) + c2w[:3, 2] * 8 + c2w[:3, 3]

    def project(K_: np.ndarray) -> np.ndarray:  # hand-written pinhole projection
        cam = (np.linalg.inv(c2w) @ np.c_[points, np.ones(len(points))].T)[:3]
        uvw = K_ @ cam
        return (uvw[:2] / uvw[2]).T

    shifted = project(padded.K)
    assert np.allclose(shifted, project(K) + np.array([padding.left, padding.top]))
    assert np.array_equal(padded.w2c, camera.w2c)


def _np_padded_packet(packet: Packet, sides: tuple[int, int, int, int]) -> Packet:
    """The packet padded with numpy (reflect) and cameras moved by hand: the reference for the enhancers."""
    top, bottom, left, right = sides

    def views(v: ViewSet) -> ViewSet:
        cameras = []
        for camera in v.cameras:
            K = camera.K.copy()
            K[0, 2] += left
            K[1, 2] += top
            cameras.append(Camera(K, camera.w2c, camera.width + left + right, camera.height + top + bottom))
        pad = lambda t: torch.from_numpy(_np_pad(t.numpy(), sides, "reflect"))  # noqa: E731
        return dataclasses.replace(
            v, images=pad(v.images), cmaps=pad(v.cmaps), alphas=pad(v.alphas), cameras=tuple(cameras)
        )

    return dataclasses.replace(packet, references=views(packet.references), targets=views(packet.targets))


def _with_size(packet: Packet, height: int, width: int) -> Packet:
    """The packet's views resized as camera and pixels (cameras resized, tensors cut or tiled)."""

    def views(v: ViewSet) -> ViewSet:
        def fit(t: torch.Tensor) -> torch.Tensor:
            reps = (1, 1, -(-height // t.shape[-2]), -(-width // t.shape[-1]))
            return t.repeat(*reps)[..., :height, :width].contiguous()

        return dataclasses.replace(
            v,
            images=fit(v.images),
            cmaps=fit(v.cmaps),
            alphas=fit(v.alphas),
            cameras=tuple(c.resized(width, height) for c in v.cameras),
        )

    return dataclasses.replace(packet, references=views(packet.references), targets=views(packet.targets))


def _saved(tmp_path: Path, **overrides: object) -> tuple[Path, SetDiffModel]:
    config = tiny_config(**overrides)
    torch.manual_seed(0)
    model = SetDiffModel(config.model).eval()
    return save_checkpoint(tmp_path / "ckpt", model, config), model


@pytest.mark.parametrize("size", [(270, 480), (137, 251)])
@pytest.mark.parametrize("method", ["setdiff", "difix"])
def test_enhancers_return_the_input_size(tmp_path: Path, method: str, size: tuple[int, int]) -> None:
    folder, model = _saved(tmp_path, **(DIFIX if method == "difix" else {}))
    enhancer = create_enhancer(method, checkpoint=str(folder), device="cpu")
    packet = _with_size(make_packet(2, 1, seed=3), *size)
    output = enhancer.enhance(packet)
    assert output.shape == (1, 3, *size) and output.dtype == torch.float32
    assert torch.isfinite(output).all() and float(output.min()) >= 0.0 and float(output.max()) <= 1.0
    # = the model on the packet padded by numpy, cropped by slicing
    padding = padding_for(*size, 8)
    sides = (padding.top, padding.bottom, padding.left, padding.right)
    reference_packet = _np_padded_packet(packet, sides)
    if method == "difix":  # the nearest-pose reference of the one target (pose distance is padding-free)
        from setdiff_bench.enhancers.difix import nearest_pose_assignments

        [choice] = nearest_pose_assignments(packet.references.cameras, packet.targets.cameras)
        reference_packet = dataclasses.replace(
            reference_packet, references=reference_packet.references.subset([choice])
        )
        expected = enhance_packet(model, reference_packet, max_references=1, targets_per_set=1)
    else:
        expected = enhance_packet(model, reference_packet)
    height, width = size
    assert torch.equal(output, expected[..., sides[0] : sides[0] + height, sides[2] : sides[2] + width])


@pytest.mark.parametrize("method", ["setdiff", "difix"])
def test_size_at_a_multiple_is_untouched(tmp_path: Path, method: str) -> None:
    folder, model = _saved(tmp_path, **(DIFIX if method == "difix" else {}))
    enhancer = create_enhancer(method, checkpoint=str(folder), device="cpu")
    packet = make_packet(2, 2, size=(32, 48), seed=4)
    padded, padding = pad_packet(packet, 8)
    assert padded is packet and padding.is_zero
    # bit-identical to the model called directly on the packet (the code path before issue 41)
    if method == "setdiff":
        expected = enhance_packet(model, packet)
    else:  # DiFix: each target with its nearest-pose reference, one set each
        from setdiff_bench.enhancers.difix import nearest_pose_assignments

        choice = nearest_pose_assignments(packet.references.cameras, packet.targets.cameras)
        expected = torch.cat(
            [
                enhance_packet(
                    model,
                    dataclasses.replace(
                        packet, references=packet.references.subset([r]), targets=packet.targets.subset([t])
                    ),
                    max_references=1,
                    targets_per_set=1,
                )
                for t, r in enumerate(choice)
            ]
        )
    assert torch.equal(enhancer.enhance(packet), expected)
