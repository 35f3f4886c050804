"""How a fit finds its scene: the loader registry recognises the folder, or a one-line error names it."""

from __future__ import annotations

import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.errors import DatasetError
from setdiff_bench.gaussians.fit import load_fit_scene


def test_the_registry_reads_the_synthetic_scene(tiny_scene):
    assert tiny_scene.dataset == "synthetic"
    assert any(frame.mask_path is not None for frame in tiny_scene.frames)  # masks are read where present


def test_an_unknown_folder_is_refused_in_one_line_naming_it(tmp_path, capsys):
    folder = tmp_path / "holiday_photos"
    (folder / "images").mkdir(parents=True)
    (folder / "images" / "a.png").write_bytes(b"")
    with pytest.raises(DatasetError) as error:
        load_fit_scene(folder)
    message = str(error.value)
    assert len(message.splitlines()) == 1 and str(folder) in message and "--dataset" in message
    code = main(["fit", "--scene", str(folder), "--out", str(tmp_path / "m.ply"), "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "holiday_photos" in err
    assert not (tmp_path / "m.ply").exists()
