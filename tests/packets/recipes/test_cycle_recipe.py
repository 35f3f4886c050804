"""``prepare --pairs cycle[:S]``: cycle reconstruction (issue 41, Difix3D+).

The capture is ``street_00`` of the synthetic layout (``tests.packets.recipes.conftest``): its recorded frames are
lane 0's front camera at timesteps 0, 1, 3, 4, at ``(x0 + 1.5 i + 0.15 i², 0, 1.6)`` (``x0`` the scene's
jitter), looking along +x with +z up, so the camera's right axis (OpenCV +x) is world −y.  The cycle's first
fit A sees those four captures; its second fit B sees only A's renders at the same cameras moved 2 m to the
right, i.e. to ``y = −2``.  Both fitting calls are spied on; every expectation is written out by hand.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.gaussians.ply import read_ply
from setdiff_bench.gaussians.render import render
from setdiff_bench.packets.recipes import parse_pairs
from tests.packets.recipes.pairs_common import ITERATIONS, RECORDED, packets_of, prepare_pairs, spy_fits

STEPS = (0, 1, 3, 4)  # the recorded timesteps


@pytest.fixture
def fits(monkeypatch: pytest.MonkeyPatch) -> list[dict[str, Any]]:
    """Each fit made, with the views it was given (:func:`tests.packets.recipes.pairs_common.spy_fits`)."""
    return spy_fits(monkeypatch, views=True)


def test_cycle_fits_a_second_3dgs_on_renders_at_shifted_cameras(
    capture: Path, tmp_path: Path, fits: list[dict[str, Any]]
) -> None:
    out = tmp_path / "store"
    summary = prepare_pairs(capture, out, "cycle")
    # A: the scene's own fit on the four captures (timestep 3 carries the dynamic mask); then B
    assert [(c["ply"], c["frames"], c["iterations"], c["stop_after"]) for c in fits] == [
        ("lane0.ply", RECORDED, ITERATIONS, None),
        ("lane0@cycle2m.ply", RECORDED, ITERATIONS, None),
    ]
    first, second = fits
    assert first["names"] == RECORDED and first["masked"] == [False, False, True, False]
    x0 = first["centres"][0][0]
    recorded_centres = [np.array([x0 + 1.5 * i + 0.15 * i * i, 0.0, 1.6]) for i in STEPS]
    np.testing.assert_allclose(np.stack(first["centres"]), np.stack(recorded_centres), atol=1e-9)
    # B saw none of the captures: renders named <frame>@cycle2m, at the cameras 2 m to the right (world -y),
    # same orientation, no mask
    assert second["names"] == [f"{name}@cycle2m" for name in RECORDED]
    assert second["masked"] == [False] * 4
    shifted_centres = [np.array([x0 + 1.5 * i + 0.15 * i * i, -2.0, 1.6]) for i in STEPS]
    np.testing.assert_allclose(np.stack(second["centres"]), np.stack(shifted_centres), atol=1e-9)
    for before, after in zip(first["rotations"], second["rotations"], strict=True):
        np.testing.assert_allclose(after, before, atol=1e-12)
    # ... and each image is A rendered there (a camera built by hand from the shifted centre)
    # (fits run on CUDA when there is one: A is rendered there with gsplat, as the fit renders)
    backend, device = ("gsplat", "cuda") if torch.cuda.is_available() else ("torch", "cpu")
    fit_a = read_ply(out / "fits" / "street_00" / "lane0.ply").to(device)
    for k, centre in enumerate(shifted_centres):
        c2w = np.eye(4)
        c2w[:3, :3] = first["rotations"][k].T
        c2w[:3, 3] = centre
        K = np.array([[24.0, 0.0, 24.0], [0.0, 24.0, 16.0], [0.0, 0.0, 1.0]])  # the fixture's 48x32 pinhole
        with torch.no_grad():
            camera = Camera.from_c2w(c2w, K, 48, 32)
            expected = render(fit_a, [camera], backend, with_geometry=False).rgb[0].clamp(0, 1).cpu()
        torch.testing.assert_close(second["images"][k], expected, atol=1e-5, rtol=0)
        assert not torch.equal(second["images"][k], first["images"][k])
    assert summary.fits_trained == 2
    # B's renders at the recorded cameras are the targets; as in underfit, references are the recorded frames
    # less the packet's own targets: 4 - 1 = 3 references, and at most min(12 - 3, 4 - 3) = 1 target per packet
    assert packets_of(out) == {
        f"synthetic__street-00__cycle2m__{i:04d}": ([frame], set(RECORDED) - {frame})
        for i, frame in enumerate(RECORDED)
    }
    index = pd.read_parquet(out / "index.parquet")
    assert set(index["group"]) == {"cycle2m"} and set(index["fit_key"]) == {"lane0@cycle2m"}
    targets = index[index["role"] == "target"]
    assert targets["gt"].notna().all() and targets["mask"].notna().all()

    # a rerun fits nothing and writes nothing
    files = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    again = prepare_pairs(capture, out, "cycle:2.0")
    assert (again.written, again.skipped, again.fits_trained) == (0, 4, 0) and len(fits) == 2
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == files
    # B removed: A is reused, B is made again, byte-identical on the CPU, and no packet changes
    fit_b = out / "fits" / "street_00" / "lane0@cycle2m.ply"
    fit_b.unlink()
    again = prepare_pairs(capture, out, "cycle")
    assert again.fits_trained == 1 and [c["ply"] for c in fits[2:]] == ["lane0@cycle2m.ply"]
    if device == "cpu":  # gsplat's fits need not repeat bit for bit
        assert (again.written, again.skipped) == (0, 4)
        assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == files
    index = pd.read_parquet(out / "index.parquet")

    # --fits DIR: B is looked up under the same name (nothing is fitted), and the packets are the same
    elsewhere = tmp_path / "fits"
    (elsewhere / "street_00").mkdir(parents=True)
    shutil.copyfile(fit_b, elsewhere / "street_00" / fit_b.name)
    copy = tmp_path / "copy"
    with_dir = prepare_pairs(capture, copy, "cycle", fit=False, fits=elsewhere)
    assert with_dir.fits_trained == 0 and len(fits) == 3
    assert pd.read_parquet(copy / "index.parquet").equals(index)


def test_cycle_shift_parameter_label_and_direction() -> None:
    (default,) = parse_pairs(["cycle"])
    assert (default.shift, default.label) == (2.0, "cycle2m")
    left, far = parse_pairs(["cycle:-1.5,cycle:6"])
    assert (left.shift, left.label, far.shift, far.label) == (-1.5, "cycle-1.5m", 6.0, "cycle6m")
