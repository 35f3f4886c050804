"""The CLI agrees with itself: ``--device`` defaults to ``auto`` and ``--no-progress`` exists on every verb that
has a device or a progress bar; the older spellings (``prepare --quiet``, ``train --cpu``) still parse, hidden."""

from __future__ import annotations

import pytest

from setdiff_bench.cli.main import build_parser
from setdiff_bench.runtime.devices import resolve_device

# Each verb with its required arguments (parsed only; nothing runs), and whether it draws progress bars.
VERBS = {
    "ablate geometry": (["ablate", "geometry", "--packets", "p", "--out", "o"], True),
    "ablate setsize": (["ablate", "setsize", "--checkpoint", "c", "--packets", "p", "--out", "o"], True),
    "demo": (["demo"], True),
    "evaluate": (["evaluate", "run", "--packets", "p"], True),
    "fit": (["fit", "--scene", "s", "--out", "o.ply"], True),
    "prepare": (["prepare", "euvs", "--root", "r", "--fit", "--out", "o"], True),
    "render": (["render", "--ply", "m.ply", "--colmap", "c", "--out", "o"], True),
    "run": (["run", "--method", "identity", "--packets", "p"], True),
    "serve": (["serve", "--checkpoint", "c"], False),
    "synth": (["synth", "--out", "o"], True),
    "train": (["train", "--packets", "p", "--out", "o"], True),
}


@pytest.mark.parametrize("verb", sorted(VERBS))
def test_device_defaults_to_auto_and_progress_can_be_hidden(verb: str) -> None:
    argv, has_progress = VERBS[verb]
    parser = build_parser()
    args = parser.parse_args(argv)
    assert args.device == "auto"
    assert parser.parse_args([*argv, "--device", "cpu"]).device == "cpu"
    if has_progress:
        assert args.no_progress is False
        assert parser.parse_args([*argv, "--no-progress"]).no_progress is True


def test_auto_is_the_cpu_without_cuda(monkeypatch: pytest.MonkeyPatch) -> None:
    import torch

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert resolve_device("auto") == "cpu"


def test_old_spellings_still_parse_but_are_hidden(capsys: pytest.CaptureFixture[str]) -> None:
    parser = build_parser()
    assert parser.parse_args(VERBS["prepare"][0] + ["--quiet"]).no_progress is True
    assert parser.parse_args(VERBS["train"][0] + ["--cpu"]).device == "cpu"
    for verb, hidden in (("prepare", "--quiet"), ("train", "--cpu")):
        with pytest.raises(SystemExit):
            parser.parse_args([verb, "--help"])
        shown = capsys.readouterr().out
        assert "--no-progress" in shown and "--device" in shown and hidden not in shown
