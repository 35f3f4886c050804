"""Issue 45: an error caused by one value names the parameter; the CLI prints the verb's flag for it.

The library raises with ``parameter="checkpoint"`` (``packets``, ``method``, ``source``, ``protocol``,
``config``); a Python caller reads ``checkpoint='nope': ...``, never a command-line flag, and the CLI maps the
parameter to its option through the parser (``--checkpoint nope: ...``, ``--from``: ``source``).  Each refusal
is one line on stderr, exit code 2, and writes nothing.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

import pytest

from setdiff_bench.cli.main import build_parser, command_parsers, main, parameter_options
from setdiff_bench.enhancers.base import available_methods, create_enhancer
from setdiff_bench.errors import CheckpointError, SetDiffBenchError, UsageError
from setdiff_bench.loaders import DATASETS
from setdiff_bench.models.setdiff.config_io import load_config, packaged_configs
from setdiff_bench.models.setdiff.packaged import packaged_names
from setdiff_bench.packets.store import PacketStore
from setdiff_bench.protocols import list_protocols, load_protocol
from setdiff_bench.runtime.threads import torch_threads
from tests.evaluation.run.store_fixtures import StoreSpec, build_store

SHIPPED = ", ".join(packaged_names("enhancer"))
METHODS = ", ".join(sorted(available_methods()))
PROTOCOLS = ", ".join(list_protocols())
CONFIGS = ", ".join(sorted(packaged_configs()))
NOT_A_CHECKPOINT = "not a checkpoint: no model.safetensors and no 'latest' file"
NEEDS_MODEL = (
    "method 'difix' needs a trained model: pass a checkpoint folder, a training output folder or a shipped "
    "model's name (train one with `setdiff-bench train`)"
)
NO_STORE = "no index.parquet here; create the store with `setdiff-bench prepare`"


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A store of 48x32 packets, all in the ``test`` split."""
    with torch_threads(1):
        return build_store(tmp_path_factory.mktemp("store"), StoreSpec())


@pytest.fixture(scope="module")
def finished_run(store: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished ``identity`` run on :func:`store` (PSNR only)."""
    run = tmp_path_factory.mktemp("runs") / "identity"
    argv = ["run", "--method", "identity", "--packets", str(store), "--out", str(run)]
    assert main([*argv, "--metrics", "psnr", "--no-progress"]) == 0
    return run


def snapshot(folder: Path) -> dict[str, int]:
    """Every file and folder under ``folder`` with its modification time (ns)."""
    return {str(path.relative_to(folder)): path.stat().st_mtime_ns for path in sorted(folder.rglob("*"))}


def refusal(argv: list[str], capsys: pytest.CaptureFixture[str], *watched: Path) -> str:
    """Run ``argv``; assert exit 2, one stderr line, and nothing written under the watched folders.  The line."""
    before = [snapshot(folder) for folder in watched]
    capsys.readouterr()
    try:
        code = main(argv)
    except SystemExit as stop:  # an argparse refusal exits from the parser
        code = stop.code
    assert code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert [snapshot(folder) for folder in watched] == before
    return lines[0]


#: (argv after the verb's store/output words are filled in, expected line); ``{store}``, ``{cwd}`` and ``{run}``
#: are replaced by the store, the working folder (holding an empty ``emptydir``) and a finished run.
CASES: list[tuple[list[str], str]] = [
    (
        ["run", "--method", "setdiff", "--checkpoint", "nope", "--packets", "{store}", "--out", "out"],
        f"setdiff-bench run: error: --checkpoint nope: checkpoint not found (shipped models: {SHIPPED})",
    ),
    (
        ["run", "--method", "setdiff", "--checkpoint", "emptydir", "--packets", "{store}", "--out", "out"],
        f"setdiff-bench run: error: --checkpoint {{cwd}}/emptydir: {NOT_A_CHECKPOINT}",
    ),
    (
        ["run", "--method", "difix", "--packets", "{store}", "--out", "out"],
        f"setdiff-bench run: error: --checkpoint: {NEEDS_MODEL}",
    ),
    (
        ["run", "--method", "nope", "--packets", "{store}", "--out", "out"],
        f"setdiff-bench run: error: --method: unknown method 'nope'; available: {METHODS}",
    ),
    (
        ["run", "--method", "precomputed", "--packets", "{store}", "--out", "out"],
        "setdiff-bench run: error: --from: method 'precomputed' needs a folder of enhanced images",
    ),
    (
        ["run", "--method", "precomputed", "--from", "nowhere", "--packets", "{store}", "--out", "out"],
        "setdiff-bench run: error: --from nowhere: precomputed images folder not found",
    ),
    (
        ["run", "--method", "identity", "--from", "x", "--packets", "{store}", "--out", "out"],
        "setdiff-bench run: error: --method: method 'identity' does not take --from (it takes: no options)",
    ),
    (
        ["run", "--method", "reproject", "-o", "nope=1", "--packets", "{store}", "--out", "out"],
        "setdiff-bench run: error: --method: method 'reproject' does not take nope (it takes: "
        "alpha_threshold, --device, min_weight, surface, tolerance)",
    ),
    (
        ["run", "--method", "identity", "--packets", "nostore", "--out", "out"],
        f"setdiff-bench run: error: --packets nostore: {NO_STORE}",
    ),
    (
        ["evaluate", "{run}", "--profile", "paper", "--packets", "nostore", "--no-progress"],
        f"setdiff-bench evaluate: error: --packets nostore: {NO_STORE}",
    ),
    (
        ["serve", "--checkpoint", "nope"],
        f"setdiff-bench serve: error: --checkpoint nope: checkpoint not found (shipped models: {SHIPPED})",
    ),
    (
        ["serve", "--checkpoint", "emptydir"],
        f"setdiff-bench serve: error: --checkpoint emptydir: {NOT_A_CHECKPOINT}",
    ),
    (
        ["train", "--config", "nope", "--packets", "{store}", "--out", "out"],
        f"setdiff-bench train: error: --config nope: config file not found (packaged configs: {CONFIGS})",
    ),
    (
        ["prepare", "synthetic", "--root", ".", "--protocol", "nope", "--fit", "--out", "out"],
        f"setdiff-bench prepare: error: --protocol: unknown protocol 'nope'; packaged: {PROTOCOLS} "
        "(or pass a path to a .toml file)",
    ),
    (
        ["prepare", "synthetic", "--root", ".", "--protocol", "mine.toml", "--fit", "--out", "out"],
        "setdiff-bench prepare: error: --protocol mine.toml: protocol file not found",
    ),
    (
        ["prepare", "nope", "--root", ".", "--fit", "--out", "out"],
        "setdiff-bench prepare: error: argument DATASET: invalid choice: 'nope' (choose from "
        + ", ".join(f"'{key}'" for key in DATASETS)
        + ") (see setdiff-bench prepare --help)",
    ),
]


@pytest.mark.parametrize(("argv", "expected"), CASES, ids=lambda value: " ".join(value)[:60])
def test_cli_names_the_flag(
    argv: list[str],
    expected: str,
    store: Path,
    finished_run: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The exact line, exit 2, and nothing written: not in the working folder, the store or the run."""
    (tmp_path / "emptydir").mkdir()
    monkeypatch.chdir(tmp_path)
    words = [word.format(store=store, run=finished_run) for word in argv]
    assert refusal(words, capsys, tmp_path, store, finished_run) == expected.format(cwd=tmp_path.resolve())


PYTHON_CASES: list[tuple[Callable[[], object], str, str]] = [
    (lambda: create_enhancer("difix"), "checkpoint", f"checkpoint: {NEEDS_MODEL}"),
    (
        lambda: create_enhancer("setdiff", checkpoint="nope"),
        "checkpoint",
        f"checkpoint='nope': checkpoint not found (shipped models: {SHIPPED})",
    ),
    (
        lambda: create_enhancer("precomputed"),
        "source",
        "source: method 'precomputed' needs a folder of enhanced images",
    ),
    (
        lambda: create_enhancer("precomputed", source="nowhere"),
        "source",
        "source='nowhere': precomputed images folder not found",
    ),
    (
        lambda: create_enhancer("nope"),
        "method",
        f"method: unknown method 'nope'; available: {METHODS}",
    ),
    (
        lambda: create_enhancer("identity", source="x"),
        "method",
        "method: method 'identity' does not take source (it takes: no options)",
    ),
    (
        lambda: create_enhancer("reproject", nope=1),
        "method",
        "method: method 'reproject' does not take nope (it takes: alpha_threshold, device, min_weight, surface, "
        "tolerance)",
    ),
    (lambda: PacketStore("nostore"), "packets", f"packets='nostore': {NO_STORE}"),
    (
        lambda: load_config("nope"),
        "config",
        f"config='nope': config file not found (packaged configs: {CONFIGS})",
    ),
    (
        lambda: load_protocol("nope"),
        "protocol",
        f"protocol: unknown protocol 'nope'; packaged: {PROTOCOLS} (or pass a path to a .toml file)",
    ),
    (lambda: load_protocol("mine.toml"), "protocol", "protocol='mine.toml': protocol file not found"),
]


@pytest.mark.parametrize(("call", "parameter", "expected"), PYTHON_CASES)
def test_python_names_the_parameter(
    call: Callable[[], object],
    parameter: str,
    expected: str,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A Python caller sees the parameter it passed (``checkpoint=``), never a command-line flag."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SetDiffBenchError) as caught:
        call()
    assert caught.value.parameter == parameter
    assert str(caught.value) == caught.value.one_line() == expected
    assert "--" not in expected


def test_one_line_forms() -> None:
    """Python form, command-line form, positional argument, and a parameter the command line lacks."""
    error = CheckpointError("checkpoint not found", "my ckpt", parameter="checkpoint")
    assert error.one_line() == "checkpoint='my ckpt': checkpoint not found"
    assert error.one_line({"checkpoint": "--checkpoint"}) == "--checkpoint 'my ckpt': checkpoint not found"
    assert error.one_line({"checkpoint": ""}) == "my ckpt: checkpoint not found"  # a positional argument
    assert error.one_line({"out": "--out"}) == "my ckpt: checkpoint not found"  # as before the parameter
    missing = UsageError("needs a folder", parameter="source")
    assert missing.one_line() == "source: needs a folder"
    assert missing.one_line({"source": "--from"}) == "--from: needs a folder"
    assert missing.one_line({}) == "source: needs a folder"
    plain = UsageError("bad", "file.txt")
    assert plain.parameter is None
    assert plain.one_line() == plain.one_line({"checkpoint": "--checkpoint"}) == "file.txt: bad"


def test_parameter_options_follow_the_parser() -> None:
    """``dest`` → option string of the verb (and sub-command) the words went through."""

    def options(*words: str) -> dict[str, str]:
        parser = build_parser(list(words))
        args, _ = parser.parse_known_args(list(words))
        return parameter_options(parser, args)

    run = options("run", "--method", "identity", "--packets", "p")
    assert run["source"] == "--from"
    assert run["checkpoint"] == "--checkpoint"
    assert run["packets"] == "--packets"
    prepare = options("prepare", "synthetic", "--root", ".", "--fit", "--out", "o")
    assert prepare["dataset"] == ""
    assert prepare["protocol"] == "--protocol"
    setsize = options("ablate", "setsize", "--checkpoint", "c", "--packets", "p", "--out", "o")
    assert setsize["checkpoint"] == "--checkpoint"
    parser = build_parser(["ablate", "setsize"])
    args, _ = parser.parse_known_args(
        ["ablate", "setsize", "--checkpoint", "c", "--packets", "p", "--out", "o"]
    )
    assert [p.prog for p in command_parsers(parser, args)] == [
        "setdiff-bench",
        "setdiff-bench ablate",
        "setdiff-bench ablate setsize",
    ]


def test_prepare_dataset_choices_are_the_loader_registry() -> None:
    """``prepare``'s dataset positional offers exactly the loaders' keys, in order."""
    from setdiff_bench.cli import prepare

    parser = argparse.ArgumentParser()
    prepare.add_arguments(parser)
    (action,) = [a for a in parser._actions if a.dest == "dataset"]
    assert tuple(action.choices) == tuple(DATASETS)
