"""The dataset registry and `setdiff-bench list scenes`."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.errors import UsageError
from setdiff_bench.loaders import (
    DATASETS,
    SCENE_DETECTORS,
    detect_dataset,
    list_scenes,
    load_scenes,
    loader_options,
)
from tests.loaders.loader_fixtures import write_euvs_scene


@pytest.fixture
def euvs_root(tmp_path):
    rng = np.random.default_rng(71)
    write_euvs_scene(tmp_path / "Level 1" / "nuplan_vegas_location_1", rng)
    write_euvs_scene(tmp_path / "Level 3" / "MARS_location_62_scene_03", rng)
    return tmp_path


def test_registry_is_lazy_and_complete():
    code = (
        "import sys, setdiff_bench.loaders as l; "
        "print(sorted(l.DATASETS)); print(any(m.startswith('setdiff_bench.loaders.') for m in sys.modules)); "
        "print('torch' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.split("\n")
    assert out[0] == str(
        sorted(["colmap", "dl3dv", "euvs", "nerfstudio", "nuscenes", "paralane", "synthetic"])
    )
    assert out[1] == "False" and out[2] == "False"
    for spec in DATASETS.values():
        assert callable(spec.load_lister()) and callable(spec.load_loader())


def touch(folder, *names):
    for name in names:
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text("")
    return folder


def test_a_scene_folder_is_recognised_by_its_files_most_specific_layout_first(tmp_path):
    assert {key for key, _ in SCENE_DETECTORS} <= set(DATASETS)
    colmap = ("sparse/0/cameras.bin", "sparse/0/images.bin")
    folders = {
        "synthetic": touch(tmp_path / "s", "scene.json", "test_set.txt", *colmap),  # also an EUVS layout
        "euvs": touch(tmp_path / "e", "test_set.txt", *colmap),  # also a COLMAP scene
        "colmap": touch(tmp_path / "c", "sparse/cameras.txt", "sparse/images.txt", "transforms.json"),
        "nerfstudio": touch(tmp_path / "n", "transforms.json"),
    }
    for key, folder in folders.items():
        assert detect_dataset(folder) == key
    assert detect_dataset(touch(tmp_path / "x", "scene.json", "images/a.png")) is None
    assert detect_dataset(tmp_path / "missing") is None


def test_options_are_checked(euvs_root):
    assert loader_options("euvs") == {
        "level": None,
        "masks": "require_test",
        "poses": "sparse",
        "distortion": "keep",
    }
    with pytest.raises(UsageError, match="no option 'sweeps'"):
        load_scenes("euvs", euvs_root, sweeps=False)
    with pytest.raises(UsageError, match="unknown dataset 'kitti'"):
        list_scenes("kitti", euvs_root)
    assert list_scenes("euvs", euvs_root, masks="optional") == [
        "Level 1/nuplan_vegas_location_1",
        "Level 3/MARS_location_62_scene_03",
    ]


def test_cli_list_scenes_table_and_json(euvs_root, capsys):
    assert main(["list", "scenes", "--dataset", "euvs", "--root", str(euvs_root)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"euvs: 2 scenes under {euvs_root}"
    assert lines[1].split() == ["SCENE", "FRAMES", "CAMERAS", "TRAVERSALS", "TRAIN", "TEST", "SIZE"]
    # name has a space; the counts are the last six columns
    assert lines[2].startswith("Level 1/nuplan_vegas_location_1") and lines[2].split()[-6:] == [
        "5",
        "2",
        "2",
        "3",
        "2",
        "32x24",
    ]
    assert (
        main(
            [
                "list",
                "scenes",
                "--dataset",
                "euvs",
                "--root",
                str(euvs_root),
                "--scene",
                "MARS_location_62_scene_03",
                "--json",
                "-o",
                "level=3",
            ]
        )
        == 0
    )
    row = json.loads(capsys.readouterr().out)
    assert row == {
        "scene": "Level 3/MARS_location_62_scene_03",
        "frames": 5,
        "cameras": 2,
        "traversals": 2,
        "train": 3,
        "test": 2,
        "sizes": ["32x24"],
    }
    assert main(["list", "scenes", "--dataset", "euvs", "--root", str(euvs_root), "--names-only"]) == 0
    assert capsys.readouterr().out.splitlines() == [
        "Level 1/nuplan_vegas_location_1",
        "Level 3/MARS_location_62_scene_03",
    ]


def test_cli_bad_root_exits_2_with_one_line(tmp_path, capsys):
    missing = tmp_path / "nowhere"
    assert main(["list", "scenes", "--dataset", "nuscenes", "--root", str(missing)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err == f"setdiff-bench list: error: {missing}: dataset root not found or not a folder\n"
    (tmp_path / "empty").mkdir()
    assert main(["list", "scenes", "--dataset", "euvs", "--root", str(tmp_path / "empty")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no EUVS scenes found" in err


def test_cli_bad_option_exits_2(euvs_root, capsys):
    assert main(["list", "scenes", "--dataset", "euvs", "--root", str(euvs_root), "-o", "bogus"]) == 2
    assert "KEY=VALUE" in capsys.readouterr().err
