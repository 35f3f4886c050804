"""Issue 45 papercut: ``setdiff-bench weights <sub-command> --help`` prints that sub-command's own help
(every sub-command printed the same text before), and every existing ``weights`` invocation and error
message still works.

The expected options of each sub-command are written out here by hand (what the README, docs and the
old single parser accepted for it), not read from the parser under test.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from setdiff_bench.cli.main import build_parser, main

#: Each sub-command's own options (beyond -h), and options of the others that its help must not show.
OWN_OPTIONS = {
    "lpips": {"--from", "--download", "--check", "--net", "--out"},
    "list": set(),
    "verify": set(),
    "export": {"--name", "--to", "--force", "--guidance-scale", "--average"},
}
ALL_OPTIONS = set().union(*OWN_OPTIONS.values())


def sub_help(sub: str, capsys: pytest.CaptureFixture[str]) -> str:
    with pytest.raises(SystemExit) as exit_:
        main(["weights", sub, "--help"])
    assert exit_.value.code == 0
    return capsys.readouterr().out


@pytest.mark.parametrize("sub", sorted(OWN_OPTIONS))
def test_each_sub_command_has_its_own_help(sub: str, capsys: pytest.CaptureFixture[str]) -> None:
    text = sub_help(sub, capsys)
    assert text.startswith(f"usage: setdiff-bench weights {sub} ")
    shown = {option for option in ALL_OPTIONS if f"{option} " in text or text.endswith(option)}
    assert shown == OWN_OPTIONS[sub]
    examples = [line.strip() for line in text.splitlines() if line.startswith("    setdiff-bench weights ")]
    assert examples and all(example.startswith(f"setdiff-bench weights {sub}") for example in examples)


def test_the_sub_helps_differ(capsys: pytest.CaptureFixture[str]) -> None:
    texts = {sub: sub_help(sub, capsys) for sub in OWN_OPTIONS}
    with pytest.raises(SystemExit):
        main(["weights", "--help"])
    top = capsys.readouterr().out
    assert len({*texts.values(), top}) == len(texts) + 1
    for sub in OWN_OPTIONS:  # the verb's help lists every sub-command
        assert f"\n    {sub} " in top


#: Invocations documented in the README, docs/ and the old ``weights --help``, as the old parser read them.
INVOCATIONS = [
    (["lpips"], {"model": "lpips", "source": None, "download": False, "check": False, "net": "all"}),
    (["lpips", "--download"], {"model": "lpips", "download": True}),
    (["lpips", "--check", "--net", "alex"], {"model": "lpips", "check": True, "net": "alex"}),
    (["lpips", "--from", "a.tar.gz", "--net", "alex", "--out", "o"], {"source": "a.tar.gz", "out": "o"}),
    (["list"], {"model": "list"}),
    (["verify"], {"model": "verify", "names": []}),
    (["verify", "tiny_setdiff", "tiny_difix"], {"names": ["tiny_setdiff", "tiny_difix"]}),
    (
        ["export", "runs/x", "--name", "n", "--to", "d", "--average", "2", "--guidance-scale", "1.5"],
        {"model": "export", "names": ["runs/x"], "name": "n", "to": Path("d"), "average": 2, "force": False},
    ),
    (["export", "runs/x", "--name", "tiny_setdiff", "--force"], {"force": True, "to": None}),
    (["export", "--name", "n", "runs/x"], {"names": ["runs/x"], "name": "n"}),
]


@pytest.mark.parametrize(
    ("words", "expected"), INVOCATIONS, ids=lambda v: " ".join(v) if isinstance(v, list) else ""
)
def test_documented_invocations_parse_as_before(words: list[str], expected: dict[str, object]) -> None:
    argv = ["weights", *words]
    args = build_parser(argv).parse_args(argv)
    assert {key: getattr(args, key) for key in expected} == expected


#: Bad invocations and the one line each prints (exit 2).
REFUSALS = [
    (["weights"], "setdiff-bench weights: error: the following arguments are required: SUBCOMMAND"),
    (
        ["weights", "export", "--name", "x"],
        "setdiff-bench weights: error: export: export needs one training run folder and --name NAME",
    ),
    (
        ["weights", "lpips", "--out", "o"],
        "setdiff-bench weights: error: --out only applies together with --from",
    ),
    (
        ["weights", "verify", "no_such_model"],
        "setdiff-bench weights: error: NAME: no shipped model 'no_such_model'; shipped: ",
    ),
    (
        ["weights", "list", "--net", "alex"],
        "setdiff-bench weights: error: unrecognized arguments: --net alex "
        "(see setdiff-bench weights list --help)",
    ),
    (
        ["weights", "lpips", "--check", "--download"],
        "setdiff-bench weights: error: argument --download: not allowed with argument --check",
    ),
    (["weights", "nope"], "setdiff-bench weights: error: argument SUBCOMMAND: invalid choice: 'nope'"),
]


@pytest.mark.parametrize(("argv", "line"), REFUSALS, ids=lambda v: " ".join(v) if isinstance(v, list) else "")
def test_refusals_are_one_line(
    argv: list[str],
    line: str,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.chdir(tmp_path)
    try:
        code = main(argv)
    except SystemExit as exit_:
        code = exit_.code
    assert code == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and lines[0].startswith(line), lines
    assert list(tmp_path.iterdir()) == []


PROBE = """
import sys
from setdiff_bench.cli.main import main
for sub in ("lpips", "list", "verify", "export"):
    try:
        main(["weights", sub, "--help"])
    except SystemExit:
        pass
print("HEAVY", ",".join(name for name in ("torch", "pandas", "safetensors") if name in sys.modules))
"""


def test_sub_helps_import_nothing_heavy() -> None:
    """Each sub-help stays as fast as ``weights --help`` (tests/cli/test_help_latency.py checks that one)."""
    result = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, check=True)
    assert result.stdout.strip().splitlines()[-1] == "HEAVY"
