"""``setdiff-bench fit``: end to end on the tiny scene, frame lists, checkpoints, one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

from setdiff_bench.cli.main import main
from setdiff_bench.gaussians.ply import read_ply


def fit_argv(scene: Path, out: Path, *extra: str, checkpoint: Path | None = None) -> list[str]:
    """``setdiff-bench fit`` arguments fitting ``scene`` into ``out`` without a progress bar, then ``extra``;
    with ``checkpoint``, a CPU fit checkpointing there."""
    on_cpu = ["--device", "cpu", "--checkpoint", str(checkpoint)] if checkpoint else []
    return ["fit", "--scene", str(scene), "--out", str(out), "--no-progress", *on_cpu, *extra]


def test_fit_writes_a_standard_ply(tiny_scene_dir, tmp_path, capsys):
    out = tmp_path / "model.ply"
    code = main(
        fit_argv(tiny_scene_dir, out, "--preset", "tiny", "--iterations", "4", checkpoint=tmp_path / "ckpt")
    )
    assert code == 0
    model = read_ply(out)
    assert len(model) > 100 and model.sh_degree == 3
    assert "fitted" in capsys.readouterr().out
    state = json.loads((tmp_path / "ckpt" / "fit_state.json").read_text())
    assert state["iteration"] == 4
    train = (tiny_scene_dir / "train_set.txt").read_text().split()
    assert state["views"] == train


def test_fit_on_an_explicit_frame_list(tiny_scene_dir, tmp_path):
    frames = "lane1_front_000.png,lane1_front_001.png"
    code = main(
        fit_argv(
            tiny_scene_dir,
            tmp_path / "m.ply",
            "--frames",
            frames,
            "--iterations",
            "2",
            checkpoint=tmp_path / "c",
        )
    )
    assert code == 0
    assert json.loads((tmp_path / "c" / "fit_state.json").read_text())["views"] == frames.split(",")


def test_fit_errors_are_one_line(tiny_scene_dir, tmp_path, capsys):
    code = main(fit_argv(tmp_path / "missing", tmp_path / "m.ply"))
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "missing" in err
    code = main(fit_argv(tiny_scene_dir, tmp_path / "m.ply", "--frames", "nope.png"))
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "nope.png" in err
    assert not (tmp_path / "m.ply").exists()


def test_iterations_keeps_the_preset_settings():
    """Regression: ``--preset default --iterations 300`` rebuilt the schedule from scratch, turning the
    preset's disabled opacity reset (10 000) into a reset every 90 iterations and dropping its 3000
    background points."""
    from setdiff_bench.cli.fit import fit_config
    from setdiff_bench.synthetic.presets import get_preset

    preset = get_preset("default").fit
    config = fit_config("default", 300, seed=0)
    assert config.iterations == 300
    assert config.strategy.opacity_reset_every > 300  # still never reached
    assert config.background_points == preset.background_points == 3000
    assert config.strategy.max_gaussians == preset.strategy.max_gaussians == 16_000
    assert config.lr_means == preset.lr_means
    # schedule fields scale by 300 / 250 = 1.2: densify every 20 -> 24, from 25 -> 30, until 150 -> 180
    strategy = config.strategy
    assert (strategy.densify_every, strategy.densify_from, strategy.densify_until) == (24, 30, 180)
    assert config.sh_increase_every == 30
