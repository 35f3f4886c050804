"""The packaged protocol files, the scene splits, and the validator's one-line errors."""

from __future__ import annotations

import random
import re
import tomllib
from fractions import Fraction
from pathlib import Path

import pytest

from setdiff_bench.errors import ProtocolError
from setdiff_bench.protocols import list_protocols, load_protocol, protocol_dir
from setdiff_bench.protocols.scene_split import SceneSplit

FIRST_DL3DV_TEST = "0a78c25f77c1ba1d1a3f07c18c9735ae1254a9a71290734b8836eefbefaadbc7"
LAST_DL3DV_TEST = "efdf19ca82bba7bccc73f64273405d077abd61dd2f5339a0a642bc75d7d900ec"
#: (base, old, new, message) of every case of invalid_protocols.toml.
INVALID_PROTOCOLS = [
    (case["base"], case["old"], case["new"], case["message"])
    for case in tomllib.loads((Path(__file__).parent / "invalid_protocols.toml").read_text())["case"]
]


def test_packaged_protocols_state_the_papers_settings():
    paper = ["dl3dv", "euvs", "nuscenes", "paralane", "synthetic"]
    assert set(paper) <= set(list_protocols())  # plus other designs (nuscenes_drivestudio, ...)
    for name in paper:
        protocol = load_protocol(name)
        assert protocol.name == protocol.dataset == name
        assert (protocol.references.alpha, protocol.references.beta) == (0.8, 0.2)
        assert protocol.references.aggregate == "mean"
        expected_resolution = None if name in ("synthetic", "colmap", "nerfstudio") else (576, 1024)
        assert protocol.images.resolution == expected_resolution
        if name == "nuscenes":
            assert dict(protocol.packets.views) == {"train": 12, "test": 24}
            assert dict(protocol.references.count) == {"train": 6, "test": 12}
        else:
            assert dict(protocol.packets.views) == {"train": 12, "test": 16}
            assert protocol.packets.train_views == (8, 12)
    assert [g.name for g in load_protocol("euvs").groups] == ["level1", "level2", "level3"]
    assert [dict(g.scenes) for g in load_protocol("euvs").groups] == [{"level": (i,)} for i in (1, 2, 3)]
    assert load_protocol("euvs").images.masks == "dataset"
    assert load_protocol("nuscenes").images.masks == "none"  # dynamic objects kept in evaluation
    assert [g.params["views"] for g in load_protocol("dl3dv").groups] == [3, 6, 9]
    assert len(load_protocol("nuscenes").groups[0].params["sensors"]) == 6
    paralane = load_protocol("paralane")
    assert [(g.name, g.params["train_lane"], g.params["target_lane"]) for g in paralane.groups] == [
        ("single", 0, 1),
        ("double", 0, 2),
    ]
    assert {(g.params["fit_frames"], g.params["target_frames"]) for g in paralane.groups} == {(200, 25)}
    assert [g.name for g in load_protocol("synthetic").groups] == [
        "lane+1",
        "lane+2",
        "side",
        "turn",
        "interp",
    ]


def shuffled_test_scenes(split: SceneSplit, names: list[str], seed: int) -> list[str]:
    """The scenes ``split`` makes test when given ``names`` in an order shuffled with ``seed`` (sorted)."""
    shuffled = names[:]
    random.Random(seed).shuffle(shuffled)
    return sorted(n for n, s in split.assign(shuffled).items() if s == "test")


def test_interleaved_split_is_sixty_forty_and_order_independent():
    split = load_protocol("euvs").split
    assert split.test_fraction == Fraction(2, 5)
    names = [f"scene_{i:02d}" for i in range(10)]
    assert shuffled_test_scenes(split, names, seed=1) == ["scene_02", "scene_04", "scene_07", "scene_09"]
    many = split.assign([f"Level {1 + i % 3}/loc_{i:03d}" for i in range(104)])
    assert sum(s == "test" for s in many.values()) == 41  # ⌊104 · 2/5⌋
    assert split.assign(["only"]) == {"only": "train"}
    assert load_protocol("paralane").split == split and load_protocol("synthetic").split == split


def test_every_fifth_sorted_scene_is_a_nuscenes_test_scene():
    split = load_protocol("nuscenes").split
    names = [f"scene-{i:04d}" for i in range(1, 21)]
    assert shuffled_test_scenes(split, names, seed=2) == [
        "scene-0005",
        "scene-0010",
        "scene-0015",
        "scene-0020",
    ]
    assert sum(s == "test" for s in split.assign([f"scene-{i:04d}" for i in range(850)]).values()) == 170


def test_dl3dv_split_list_is_the_published_20_hashes():
    file = protocol_dir() / "splits" / "dl3dv_3dgs_enhancer_test.txt"
    hashes = file.read_text().splitlines()
    assert len(hashes) == 20 == len(set(hashes)) and all(re.fullmatch(r"[0-9a-f]{64}", h) for h in hashes)
    assert hashes[0] == FIRST_DL3DV_TEST and hashes[-1] == LAST_DL3DV_TEST
    split = load_protocol("dl3dv").split
    assignment = split.assign([f"1K/{hashes[3]}", "2K/" + "a" * 64, hashes[7]])
    assert assignment == {f"1K/{hashes[3]}": "test", "2K/" + "a" * 64: "train", hashes[7]: "test"}


def mutated(tmp_path: Path, old: str, new: str, base: str = "euvs") -> Path:
    text = (protocol_dir() / f"{base}.toml").read_text()
    assert old in text, old
    path = tmp_path / f"{base}-bad.toml"
    path.write_text(text.replace(old, new, 1))
    return path


@pytest.mark.parametrize(("base", "old", "new", "message"), INVALID_PROTOCOLS)
def test_invalid_protocol_files_name_the_file_and_key(tmp_path, base, old, new, message):
    path = mutated(tmp_path, old, new, base)
    if base == "dl3dv":  # keep the split list reachable from the copy
        (tmp_path / "splits").mkdir(exist_ok=True)
        source = protocol_dir() / "splits" / "dl3dv_3dgs_enhancer_test.txt"
        (tmp_path / "splits" / source.name).write_text(source.read_text())
    with pytest.raises(ProtocolError) as error:
        load_protocol(path)
    line = error.value.one_line()
    assert line.startswith(f"{path}: ") and message in line and "\n" not in line


def test_unknown_protocol_lists_the_packaged_ones():
    with pytest.raises(
        ProtocolError,
        match=r"unknown protocol 'waymo'.*colmap, dl3dv, dl3dv_sparse_synthetic, euvs, nerfstudio, nuscenes, ",
    ):
        load_protocol("waymo")
    with pytest.raises(ProtocolError, match="protocol file not found"):
        load_protocol("/nonexistent/p.toml")


def test_split_rules_directly():
    assert SceneSplit("every_nth", every=3).assign("abcdefg") == {
        "a": "train",
        "b": "train",
        "c": "test",
        "d": "train",
        "e": "train",
        "f": "test",
        "g": "train",
    }
    assert SceneSplit("interleaved", test_fraction=Fraction(1, 2)).assign("abcd") == {
        "a": "train",
        "b": "test",
        "c": "train",
        "d": "test",
    }
