"""PacketStore reading API, on-disk formats, the training dataset, integrity checks and CLI errors."""

from __future__ import annotations

import shutil

import numpy as np
import OpenImageIO as oiio
import pytest
import torch
from scipy.spatial.distance import pdist

from setdiff_bench.cli.main import main
from setdiff_bench.errors import PacketError
from setdiff_bench.packets.index import INDEX_FILE, SCHEMA
from setdiff_bench.packets.store import PacketStore
from tests.packets.packet_fixtures import prepare_argv


def test_index_columns_and_exr_format(prepared):
    out, _, store = prepared
    assert list(store.index.columns) == SCHEMA.names
    row = store.index.iloc[0]
    assert row["role"] == "ref" and row["view"] == 0 and len(row["K"]) == 9 and len(row["w2c"]) == 16
    K = np.asarray(row["K"]).reshape(3, 3)
    assert K[0, 0] == pytest.approx(24.0) and K[0, 2] == pytest.approx(24.0) and K[2, 2] == 1.0  # row-major
    handle = oiio.ImageInput.open(str(out / row["cmap"]))
    spec = handle.spec()
    handle.close()
    assert tuple(spec.channelnames) == ("X", "Y", "Z", "A") and spec.format == oiio.FLOAT
    assert (spec.width, spec.height) == (48, 32)
    targets = store.index[store.index["role"] == "target"]
    assert targets["gt"].notna().all() and targets["mask"].notna().all()
    assert store.index.loc[store.index["role"] == "ref", "gt"].isna().all()


def test_load_packet_views_and_errors(prepared, tmp_path):
    _, _, store = prepared
    pid = store.packet_ids(split="test")[0]
    full = store.load_packet(pid)
    assert full.references.images.shape == (4, 3, 32, 48) and full.references.alphas.shape == (4, 1, 32, 48)
    part = store.load_packet(pid, references=[2, 0], targets=[0])
    assert part.references.names == (full.references.names[2], full.references.names[0])
    assert torch.equal(part.references.cmaps[0], full.references.cmaps[2])
    assert [p.packet_id for p in store.iter_packets("test")] == store.packet_ids("test")
    assert set(store.packet_ids("train")) | set(store.packet_ids("test")) == set(store.packet_ids())
    with pytest.raises(PacketError, match="no packet"):
        store.load_packet("nope")
    with pytest.raises(PacketError, match="out of range"):
        store.load_packet(pid, targets=[99])
    with pytest.raises(PacketError, match=r"no index\.parquet"):
        PacketStore(tmp_path)


def test_verify_reports_a_changed_file(prepared, tmp_path):
    out, _, _ = prepared
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    store = PacketStore(copy)
    assert store.verify() == []
    pid = store.packet_ids()[5]
    mask = copy / store.rows(pid)["mask"].iloc[-1]
    mask.write_bytes(mask.read_bytes() + b"\0")
    (copy / store.rows(pid)["image"].iloc[0]).unlink()
    problems = store.verify()
    assert len(problems) == 2 and all(p.startswith(pid) for p in problems)
    assert any("SHA-256 mismatch" in p for p in problems) and any("missing" in p for p in problems)


def test_training_dataset_draws_reproducible_normalised_subsets(prepared):
    _, _, store = prepared
    dataset = store.training_dataset("train", min_views=5, max_views=9, seed=3)
    assert len(dataset) == len(store.packet_ids("train")) == 12
    draws = [dataset.choose(i) for i in range(len(dataset))]
    assert draws == [dataset.choose(i) for i in range(len(dataset))]  # deterministic per (seed, epoch, index)
    dataset.set_epoch(1)
    assert [dataset.choose(i) for i in range(len(dataset))] != draws
    assert store.training_dataset("train", 5, 9, seed=4).choose(0) != store.training_dataset(
        "train", 5, 9, seed=3
    ).choose(0)
    sizes = set()
    for index in range(len(dataset)):
        sample = dataset[index]
        packet = sample.packet
        refs, tgts = packet.metadata["reference_positions"], packet.metadata["target_positions"]
        n_views = len(refs) + len(tgts)
        available = len(store.rows(dataset.packet_ids[index]))
        assert min(5, available) <= n_views <= min(9, available) and len(tgts) >= 1 and len(refs) >= 1
        sizes.add(n_views)
        cameras = (*packet.references.cameras, *packet.targets.cameras)
        np.testing.assert_allclose(cameras[len(refs)].w2c, np.eye(4), atol=1e-9)
        assert pdist(np.stack([c.center for c in cameras])).max() == pytest.approx(1.0, abs=1e-9)
        gt, masks = store.load_ground_truth(packet.packet_id, tgts)
        assert torch.equal(sample.target_gt, gt) and torch.equal(sample.target_masks, masks)
        # the re-normalised C-maps stay in the cameras' frame: same projections as the stored packet
        stored = store.load_packet(packet.packet_id, refs, tgts)
        for new_views, old_views in (
            (packet.references, stored.references),
            (packet.targets, stored.targets),
        ):
            for v in range(len(new_views)):
                a = old_views.alphas[v, 0].double().numpy()
                ys, xs = np.nonzero(a > 0.98)
                new = project(
                    new_views.cameras[v], new_views.cmaps[v].double().numpy()[:, ys, xs] / a[ys, xs]
                )
                old = project(
                    old_views.cameras[v], old_views.cmaps[v].double().numpy()[:, ys, xs] / a[ys, xs]
                )
                np.testing.assert_allclose(new, old, atol=1e-3)
    assert len(sizes) > 1
    loader = torch.utils.data.DataLoader(dataset, batch_size=None, shuffle=False, collate_fn=lambda s: s)
    assert next(iter(loader)).packet.packet_id == dataset.packet_ids[0]


def project(camera, points: np.ndarray) -> np.ndarray:
    cam = points.T @ camera.w2c[:3, :3].T + camera.w2c[:3, 3]
    uv = cam @ camera.K.T
    return uv[:, :2] / uv[:, 2:]


def test_cli_errors_are_one_line(street, tmp_path, capsys):
    root, _ = street
    empty = tmp_path / "fits"
    empty.mkdir()
    code = main(prepare_argv(root, tmp_path / "o", fits=empty))
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert str(empty / "street_00" / "lane0.ply") in err and "missing 3DGS fit" in err
    assert not (tmp_path / "o" / INDEX_FILE).exists()

    code = main(prepare_argv(root, tmp_path / "o", "--protocol", "euvs"))
    err = capsys.readouterr().err.strip()
    assert code == 2 and "is for dataset 'euvs', not 'synthetic'" in err and len(err.splitlines()) == 1

    code = main(prepare_argv(tmp_path / "missing", tmp_path / "o", fits=root))
    err = capsys.readouterr().err.strip()
    assert code == 2 and "missing" in err and len(err.splitlines()) == 1

    bad = tmp_path / "bad_fits" / "street_00" / "lane0.ply"
    bad.parent.mkdir(parents=True)
    bad.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\nend_header\n")
    code = main(prepare_argv(root, tmp_path / "o", "--scene", "street_00", fits=tmp_path / "bad_fits"))
    err = capsys.readouterr().err.strip()
    assert code == 2 and str(bad) in err and len(err.splitlines()) == 1

    with pytest.raises(SystemExit) as exit_info:
        main(prepare_argv(root, tmp_path, "--fit"))
    assert exit_info.value.code == 2


def test_half_precision_cmaps_are_smaller_and_close(prepared, street, tmp_path):
    from setdiff_bench.packets.prepare import prepare

    root, _ = street
    _, _, full = prepared
    out = tmp_path / "half"
    prepare("synthetic", root, out, fits=root, scenes=["street_02"], cmap_precision="half", progress=False)
    half = PacketStore(out)
    pid = half.packet_ids()[0]
    handle = oiio.ImageInput.open(str(out / half.rows(pid)["cmap"].iloc[0]))
    assert handle.spec().format == oiio.HALF
    handle.close()
    a, b = half.load_packet(pid), full.load_packet(pid)
    np.testing.assert_allclose(a.targets.cmaps, b.targets.cmaps, rtol=2**-10, atol=1e-6)
    assert (
        half.rows(pid)["recipe"].iloc[0] != full.rows(pid)["recipe"].iloc[0]
    )  # switching precision rewrites
    assert (out / half.rows(pid)["cmap"].iloc[0]).stat().st_size < (
        full.root / full.rows(pid)["cmap"].iloc[0]
    ).stat().st_size


def test_declared_test_scenes_replace_the_protocol_split(street, tmp_path, capsys):
    """``prepare --test-scene`` makes the named scenes the test split and every other scene train (the fixture's
    60/40 rule would make street_02 the test scene)."""
    root, _ = street
    out = tmp_path / "o"
    assert main(prepare_argv(root, out, "--split", "test", "--test-scene", "street_00", "--quiet")) == 0
    index = PacketStore(out).index
    assert set(index["scene"]) == {"street_00"} and set(index["split"]) == {"test"}
    capsys.readouterr()
    code = main(prepare_argv(root, tmp_path / "x", "--test-scene", "street_09"))
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "no scene 'street_09'" in err and "street_00, street_01, street_02" in err
    assert not (tmp_path / "x").exists()
