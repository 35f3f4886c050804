"""The geometry-only ``reproject`` baseline on an analytic plane scene.

Coverage, occlusion and blend weights are derived independently here: numpy projections through
:meth:`Camera.project` (float64) and Eq. 2 written out by hand — not the enhancer's torch code.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.enhancers.base import create_enhancer
from setdiff_bench.enhancers.reproject import ReprojectConfig, ReprojectEnhancer
from setdiff_bench.errors import UsageError
from setdiff_bench.types import Packet, ViewSet
from tests.evaluation.run.store_fixtures import HEIGHT, WIDTH, camera_at, degrade, plane_view

DEPTH = 2.5


def view_set(
    cameras: list[Camera], images: list[np.ndarray] | None = None, points: list[np.ndarray] | None = None
) -> ViewSet:
    views = [plane_view(c, DEPTH) for c in cameras]
    images = images if images is not None else [v[0] for v in views]
    points = points if points is not None else [v[1] for v in views]

    def chw(arrays: list[np.ndarray]) -> torch.Tensor:
        return torch.from_numpy(np.stack(arrays).transpose(0, 3, 1, 2).copy()).float()

    return ViewSet(
        names=tuple(f"v{i}" for i in range(len(cameras))),
        images=chw(images),
        cmaps=chw(points),
        alphas=torch.ones(len(cameras), 1, HEIGHT, WIDTH),
        cameras=tuple(cameras),
    )


def packet(refs: ViewSet, targets: ViewSet) -> Packet:
    return Packet("p", "test", "unit", "g", "test", "s", refs, targets)


def coverage(target: Camera, ref: Camera) -> np.ndarray:
    """``(H, W)`` bool: the target pixel's plane point projects inside ``ref`` (numpy, float64)."""
    _, points, _ = plane_view(target, DEPTH)
    uv, z = ref.project(points.reshape(-1, 3).astype(np.float64))
    inside = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < ref.width) & (uv[:, 1] >= 0) & (uv[:, 1] < ref.height)
    return inside.reshape(target.height, target.width)


def render_of(camera: Camera, seed: int = 0) -> np.ndarray:
    return degrade(plane_view(camera, DEPTH)[0], seed)


def test_recovers_ground_truth_where_references_see_and_keeps_the_render_elsewhere() -> None:
    refs = [camera_at(-0.5), camera_at(-0.25)]
    target = camera_at(0.35)
    render = render_of(target)
    output = ReprojectEnhancer().enhance(packet(view_set(refs), view_set([target], images=[render])))[0]
    output = output.permute(1, 2, 0).numpy()
    gt = plane_view(target, DEPTH)[0]
    covered = coverage(target, refs[0]) | coverage(target, refs[1])
    assert 0.3 < covered.mean() < 0.95  # the shift leaves an uncovered strip
    interior = covered.copy()
    interior[:, :-1] &= covered[:, 1:]  # away from the coverage edge (bilinear border clamp)
    error = np.abs(output - gt)[interior]
    assert error.mean() < 0.01 and error.max() < 0.06
    assert np.abs(render - gt)[interior].mean() > 0.04  # the render really was worse
    np.testing.assert_array_equal(output[~covered], render[~covered])


def test_depth_test_rejects_an_occluded_reference() -> None:
    ref = camera_at(-0.4)
    target = camera_at(0.1)
    ref_image, ref_points, _ = plane_view(ref, DEPTH)
    region = np.zeros((HEIGHT, WIDTH), bool)
    region[8:24, 14:30] = True
    # an occluder in front of the plane: the reference sees a red surface at 40 % of the distance
    ref_points = ref_points.copy()
    ref_points[region] = ref.center + 0.4 * (ref_points[region] - ref.center)
    ref_image = ref_image.copy()
    ref_image[region] = (1.0, 0.0, 0.0)
    render = render_of(target, seed=3)
    output = (
        ReprojectEnhancer()
        .enhance(
            packet(
                view_set([ref], images=[ref_image], points=[ref_points]), view_set([target], images=[render])
            )
        )[0]
        .permute(1, 2, 0)
        .numpy()
    )
    # target pixels whose plane point projects into the occluded region of the reference (numpy)
    _, points, _ = plane_view(target, DEPTH)
    uv, _ = ref.project(points.reshape(-1, 3).astype(np.float64))
    col, row = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
    inside = (col >= 0) & (col < WIDTH) & (row >= 0) & (row < HEIGHT)
    hidden = np.zeros(len(uv), bool)
    hidden[inside] = region[row[inside], col[inside]]
    hidden = hidden.reshape(HEIGHT, WIDTH)
    assert hidden.sum() > 100
    np.testing.assert_array_equal(output[hidden], render[hidden])
    assert (output[..., 0] > 0.95).sum() <= 2 * HEIGHT  # no red copied (only bilinear fringe at the border)


def test_blend_weights_follow_equation_2() -> None:
    refs = [camera_at(-0.05, yaw_deg=20.0), camera_at(0.05)]
    target = camera_at(0.0)
    grey = [np.full((HEIGHT, WIDTH, 3), 0.2, np.float32), np.full((HEIGHT, WIDTH, 3), 0.8, np.float32)]
    render = render_of(target)
    output = ReprojectEnhancer().enhance(
        packet(view_set(refs, images=grey), view_set([target], images=[render]))
    )[0]
    # Eq. 2 by hand: 0.8·cos(view directions) + 0.2·(1 − distance / largest pairwise distance)
    centres = [c.center for c in (target, *refs)]
    d_max = max(np.linalg.norm(a - b) for a in centres for b in centres)
    weights = []
    for ref in refs:
        cos = float(target.R[2] @ ref.R[2])  # third rows of R: optical axes in world coordinates
        weights.append(0.8 * cos + 0.2 * (1 - np.linalg.norm(target.center - ref.center) / d_max))
    expected = (weights[0] * 0.2 + weights[1] * 0.8) / (weights[0] + weights[1])
    both = coverage(target, refs[0]) & coverage(target, refs[1])
    assert both.mean() > 0.5
    values = output.permute(1, 2, 0).numpy()[both]
    np.testing.assert_allclose(values, expected, atol=1e-5)


def test_invalid_geometry_and_no_references_keep_the_render() -> None:
    target = camera_at(0.0)
    render = render_of(target)
    targets = view_set([target], images=[render])
    targets.alphas = torch.zeros_like(targets.alphas)  # nothing hit: no C-map point
    out = ReprojectEnhancer().enhance(packet(view_set([camera_at(-0.1)]), targets))
    np.testing.assert_array_equal(out[0].permute(1, 2, 0).numpy(), render)
    empty = ViewSet(
        (),
        torch.zeros(0, 3, HEIGHT, WIDTH),
        torch.zeros(0, 3, HEIGHT, WIDTH),
        torch.zeros(0, 1, HEIGHT, WIDTH),
        (),
    )
    out = ReprojectEnhancer().enhance(packet(empty, view_set([target], images=[render])))
    np.testing.assert_array_equal(out[0].permute(1, 2, 0).numpy(), render)


def test_pixel_chunks_do_not_change_the_result() -> None:
    refs, target = [camera_at(-0.3), camera_at(-0.1)], camera_at(0.2)
    pk = packet(
        view_set(refs), view_set([target, camera_at(0.3)], images=[render_of(target), render_of(target, 1)])
    )
    whole = ReprojectEnhancer().enhance(pk)
    chunked = ReprojectEnhancer(ReprojectConfig(pixel_chunk=97)).enhance(pk)
    assert torch.equal(whole, chunked)


def test_registry_options_and_validation() -> None:
    enhancer = create_enhancer("reproject", tolerance=0.1)
    assert enhancer.options["tolerance"] == 0.1 and enhancer.options["device"] == "cpu"
    with pytest.raises(UsageError, match="tolerance"):
        create_enhancer("reproject", tolerance=-1.0)
    with pytest.raises(UsageError, match="does not take checkpoint "):
        create_enhancer("reproject", checkpoint="x")


@pytest.mark.gpu
def test_cuda_matches_cpu() -> None:
    refs, target = [camera_at(-0.3), camera_at(-0.1)], camera_at(0.2)
    pk = packet(view_set(refs), view_set([target], images=[render_of(target)]))
    cpu = ReprojectEnhancer().enhance(pk)
    gpu = ReprojectEnhancer(device="cuda").enhance(pk)
    torch.testing.assert_close(gpu, cpu, atol=1e-4, rtol=0)


def test_ray_surface_tolerates_cmap_points_off_the_ray() -> None:
    """Eq. 1 averages Gaussian *centres*: a large splat's centre lies off the pixel's ray.  Shifting every
    C-map point sideways within its depth plane (as such centres do) must not break reprojection with
    ``surface="ray"`` (the pixel's ray at the point's depth), while the raw points mislead it."""
    camera = camera_at(0.0)
    image, points, _ = plane_view(camera, DEPTH)
    offset = np.zeros_like(points)
    offset[..., 0] = 0.3  # 0.3 scene units sideways, at the same camera depth (camera x axis = world x here)
    shifted = points + offset
    _uv, z = camera.project(shifted.reshape(-1, 3))
    assert np.allclose(
        z.reshape(points.shape[:2]), camera.project(points.reshape(-1, 3))[1].reshape(points.shape[:2])
    )
    render = render_of(camera)
    target = view_set([camera], images=[render], points=[shifted])
    reference = view_set([camera], images=[image], points=[shifted])
    ray = ReprojectEnhancer(ReprojectConfig(surface="ray")).enhance(packet(reference, target))[0]
    np.testing.assert_allclose(ray.permute(1, 2, 0).numpy(), image, atol=1e-5)
    raw = ReprojectEnhancer(ReprojectConfig(surface="cmap")).enhance(packet(reference, target))[0]
    assert np.abs(raw.permute(1, 2, 0).numpy() - image).mean() > 0.01
