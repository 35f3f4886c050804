"""Issue 45: every shell command of README.md that needs no external data runs, as written, chained in one
folder (later commands read what earlier ones wrote); the others are parsed.

Commands are read from the README itself: every line of its ``bash`` blocks (``\\`` continuations joined,
``&&`` chains split, trailing ``# comments`` dropped), its ``python`` block, and every inline code span that
starts with ``setdiff-bench``, ``python``, ``pip``, ``ruff`` or ``.ci/run``.  Each must be listed in exactly
one table below, so a command added to the README fails :func:`test_every_readme_command_is_accounted_for`
until it is run or the reason it is not is written down.

The chain runs in a fresh folder with the repository's ``examples/`` linked in (the README's commands are
written for a clone's root), through the help-examples helpers (:func:`tests.cli.helpers.run_example`, whose
``small`` changes sizes only).  The one size change is the README's own: the demo runs at ``--preset tiny``
(README: "Presets (``--preset tiny|default|full``)"), whose outputs are in the same places.  The service
commands name port 50051: the plain one keeps it when it is free (its client then runs exactly as written); the
TLS one, only started, takes a free port (``small``: ``--port 0``).

=============================================================================  =========================================
README command                                                                 here
=============================================================================  =========================================
``python3 -m setdiff_bench weights lpips --download``                          run (a no-op once the weights resolve,
                                                                               as in CI, whose first command fetched
                                                                               them; skipped where they do not: it
                                                                               would need the network)
``python3 -m setdiff_bench demo`` (inline ``setdiff-bench demo``)              run, ``--preset tiny``
``setdiff-bench list datasets`` / ``list methods`` / ``weights list``          run
``setdiff-bench report --runs runs/demo/work/runs ... --out runs/report``      run on the demo's runs
the Python API block (``sb.PacketStore("runs/demo/work/packets")`` ...)        run in the demo's folder
``setdiff-bench serve --checkpoint tiny_setdiff --port 50051``                 run while the next command drives it
                                                                               (another free port, and ``--address``
                                                                               for the client, if 50051 is taken)
``python3 examples/drive_packets.py --packets runs/demo/work/packets ...``      run against it: one PNG per target
``umask 077; python3 -c "import secrets; ..." > token``                        run
``setdiff-bench serve ... --host 0.0.0.0 --tls-cert server.pem ...``           run until it listens, on a free port
                                                                               (the test makes ``server.pem`` /
                                                                               ``server.key``)
the fox walk-through (``R=/data/fox`` ... ``leaderboard ... --out runs/fox``)  parsed; the block passes ``bash -n``
                                                                               (needs the instant-ngp fox capture)
``setdiff-bench list scenes --dataset euvs --root /data/EUVS`` and the EUVS    parsed (needs EUVS; the later ones read
``prepare`` / ``train`` / ``run`` / ``leaderboard`` / ``ablate`` lines         what ``prepare euvs`` writes)
``setdiff-bench fit --scene data/synthetic/scene_0000_00 --out lane0.ply``     parsed (no README command writes
                                                                               ``data/synthetic``)
``python3 examples/drive_packets.py --packets STORE ... --address HOST:50051``  options checked against its ``--help``
inline commands with placeholders (``D``, ``R``, ``RUN_A``, ``STORE``,         parsed with the placeholders filled,
``tiny_setdiff|sd_turbo_setdiff``, ``...``)                                    each alternative; ``...``: options
                                                                               checked against the verb's parser
inline names of the program or a verb (```setdiff-bench serve``` ...)          the verb's ``--help`` is built
``pip install ...`` / ``python3 -m pip install ...``                           not run: they install packages (the
                                                                               environment under test is that install)
``setdiff-bench demo --benchmark sparse``                                      not run here: run at ``--preset tiny``
                                                                               by tests/pipeline/demo/test_demo_sparse.py
``python3 -m pytest -q``, ``.ci/run``                                          not run: they are this test suite
``ruff check .``, ``ruff format --check .``                                    not run here: tests/core/test_style.py
=============================================================================  =========================================

Cost, measured with ``--durations`` on the shared 2-core machine: 77 s of CPU (user + system, the whole module
with its subprocesses); wall time 135 s at load average 5 and 102 s at load average 4 (two to three other busy
processes per core).  At load 4: the tiny demo 47 s, serve and drive 16 s, the Python block 14 s (a fresh
interpreter loads torch and ``tiny_setdiff``), the TLS serve 13 s (start-up only), the report 6 s, the
listings 5 s; the parse checks take milliseconds.  The chain runs one process at a time but for serve and its
client, so on an otherwise idle 2-core machine its wall time is about its CPU time.  Nothing is marked slow: no
faster test runs these commands.
"""

from __future__ import annotations

import argparse
import ast
import os
import re
import shlex
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.cli.main import build_parser
from tests.cli.helpers import ROOT, command_environment, run_example, run_shell, served

README = ROOT / "README.md"

#: Commands run in the chain (with the change said in the module docstring).
RUN = {
    "python3 -m setdiff_bench weights lpips --download",
    "python3 -m setdiff_bench demo",
    "setdiff-bench demo",
    "setdiff-bench list datasets",
    "setdiff-bench list methods",
    "setdiff-bench weights list",
    "setdiff-bench report --runs runs/demo/work/runs --packets runs/demo/work/packets --out runs/report",
    "python:api",
    "setdiff-bench serve --checkpoint tiny_setdiff --port 50051",
    "python3 examples/drive_packets.py --packets runs/demo/work/packets --out enhanced",
    'umask 077; python3 -c "import secrets; print(secrets.token_urlsafe(32))" > token',
    "setdiff-bench serve --checkpoint tiny_setdiff --host 0.0.0.0 --port 50051 --tls-cert server.pem "
    "--tls-key server.key --token-file token",
}
#: What marks a command as needing external data (its shell lines pass ``bash -n``; ``setdiff-bench`` ones are
#: parsed, :func:`test_parsed_commands_parse`), with the reason.
EXTERNAL_DATA = {
    "/data/": "a dataset downloaded separately",
    "$R": "the instant-ngp fox capture (R=/data/fox)",
    "packets/fox": "packets of the fox capture",
    "runs/fox": "runs on the fox capture",
    "packets/euvs": "packets of EUVS",
    "runs/euvs": "runs on EUVS",
    "data/synthetic/scene_0000_00": "a synthetic scene no README command writes",
}
#: Placeholder words of commands written for the reader to fill, and a value each is parsed with.
PLACEHOLDERS = {"D": "synthetic", "R": "/data/root", "RUN_A": "runs/a", "RUN_B": "runs/b", "STORE": "packets"}
PLACEHOLDERS |= {"DIR": "out", "OUT": "out", "HOST": "localhost"}
#: Commands neither run nor parsed here, with the reason.
NOT_RUN = {
    'python3 -m pip install torch==2.13.0 -e ".[model]"': "installs packages",
    'python3 -m pip install torch==2.13.0 -e ".[model,test]"': "installs packages",
    "pip install -e .": "installs packages",
    'pip install -e ".[serve]"': "installs packages",
    "setdiff-bench demo --benchmark sparse": "run at --preset tiny by tests/pipeline/demo/test_demo_sparse.py",
    "python3 examples/alpasim_rollout.py": "its renderer and proxy calls are tests/serve/test_sensorsim.py's",
    "python3 -m pytest -q": "this test suite",
    ".ci/run": "CI's entry point: this test suite",
    "ruff check .": "tests/core/test_style.py",
    "ruff format --check .": "tests/core/test_style.py",
}
#: Inline names of the program or one of its verbs (not commands): their ``--help`` is built.
NAMES = {"setdiff-bench", "python3 -m setdiff_bench", "setdiff-bench synth", "setdiff-bench serve"}


def _strip_comment(line: str) -> str:
    return re.sub(r"\s+#\s.*$", "", line).strip()


def readme_commands(text: str) -> list[str]:
    """Every command of the README (module docstring), in order; the Python block as ``python:api``."""
    commands: list[str] = []
    for language, body in re.findall(r"```([a-z]*)\n(.*?)```", text, flags=re.S):
        if language == "python":
            commands.append("python:api")
        if language != "bash":
            continue
        for line in body.replace("\\\n", " ").splitlines():
            line = " ".join(_strip_comment(line).split())
            if line and not line.startswith("#"):
                commands.extend(part.strip() for part in line.split(" && "))
    prose = re.sub(r"```.*?```", "", text, flags=re.S)
    for span in re.findall(r"`([^`]+)`", prose):
        span = " ".join(span.split())
        if re.match(r"(setdiff-bench|python3?|pip|ruff|\.ci/run)(\s|$)", span):
            commands.append(span)
    return list(dict.fromkeys(commands))


def external_reason(command: str) -> str | None:
    return next((why for needle, why in EXTERNAL_DATA.items() if needle in command), None)


def has_placeholder(command: str) -> bool:
    return (
        "..." in command
        or "|" in command.split(" ", 2)[-1]
        or any(w in PLACEHOLDERS for w in command.split())
    )


def treatment(command: str) -> str:
    """``run``, ``not run``, ``name``, ``external`` or ``placeholder`` (checked by the tests below)."""
    if command in RUN:
        return "run"
    if command in NOT_RUN:
        return "not run"
    if command in NAMES:
        return "name"
    if external_reason(command):
        return "external"
    if has_placeholder(command):
        return "placeholder"
    return "unaccounted"


COMMANDS = readme_commands(README.read_text(encoding="utf-8"))


def test_every_readme_command_is_accounted_for() -> None:
    """Each README command is run, parsed or not run for a written reason; each run one is in the README."""
    assert [c for c in COMMANDS if treatment(c) == "unaccounted"] == []
    assert sorted(RUN - set(COMMANDS)) == []  # the README no longer has it: update the table
    assert "setdiff-bench list methods" in COMMANDS and "python:api" in COMMANDS  # extraction sanity


def test_commands_are_extracted_whole() -> None:
    text = (
        "x `setdiff-bench a\nb` y\n```bash\nfoo --x 1 \\\n    --y 2   # note\n# heading\na && b\n```\n"
        "```python\nprint(1)\n```\n`python3 -m pytest -q` `--flag`"
    )
    assert readme_commands(text) == [
        "foo --x 1 --y 2",
        "a",
        "b",
        "python:api",
        "setdiff-bench a b",
        "python3 -m pytest -q",
    ]


def _argvs(command: str) -> list[list[str]]:
    """The argument words of a ``setdiff-bench`` / ``python3 -m setdiff_bench`` command, placeholders filled
    (an ``a|b`` value gives one argv per alternative)."""
    rest = re.split(r"^(?:setdiff-bench|python3 -m setdiff_bench)\s*", command, maxsplit=1)[-1]
    rest = rest.replace("$R", "/data/fox")
    argv = [PLACEHOLDERS.get(word, word) for word in shlex.split(rest)]
    alternatives = next((w.split("|") for w in argv if "|" in w), None)
    if alternatives is None:
        return [argv]
    return [[alt if "|" in w else w for w in argv] for alt in alternatives]


def verb_parser(argv: list[str]) -> argparse.ArgumentParser:
    """The (sub-)parser the leading non-option words of ``argv`` name (the top parser for none)."""
    parser = build_parser(argv)
    for word in argv:
        sub = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)
        if sub is None or word not in sub.choices:
            break
        parser = sub.choices[word]
    return parser


PARSED = [
    c for c in COMMANDS if c.startswith(("setdiff-bench ", "python3 -m setdiff_bench ")) and c not in NAMES
]


@pytest.mark.parametrize("command", PARSED)
def test_parsed_commands_parse(command: str) -> None:
    """Every ``setdiff-bench`` command parses as written (with ``...``: its options exist in its verb)."""
    for argv in _argvs(command):
        if "..." not in argv:
            build_parser(argv).parse_args(argv)
            continue
        known = {option for action in verb_parser(argv)._actions for option in action.option_strings}
        assert {w for w in argv if w.startswith("-")} <= known, command


@pytest.mark.parametrize("name", sorted(NAMES))
def test_named_verbs_exist(name: str) -> None:
    """A verb named in the prose exists: its help is built (the program's own for the bare name)."""
    argv = _argvs(name)[0]
    assert verb_parser(argv).format_help().startswith(" ".join(["usage: setdiff-bench", *argv]))


def test_shell_blocks_are_valid_bash() -> None:
    text = README.read_text(encoding="utf-8")
    for body in re.findall(r"```bash\n(.*?)```", text, flags=re.S):
        result = subprocess.run(["bash", "-n"], input=body, capture_output=True, text=True)
        assert result.returncode == 0, (body, result.stderr)


def test_drive_packets_takes_the_options_the_readme_gives() -> None:
    drives = [c for c in COMMANDS if c.startswith("python3 examples/drive_packets.py")]
    assert len(drives) == 2
    result = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "drive_packets.py"), "--help"],
        capture_output=True,
        text=True,
        env=command_environment(),
    )
    assert result.returncode == 0, result.stderr
    for command in drives:
        options = {w for w in shlex.split(command) if w.startswith("--")}
        assert options and all(f"{option} " in result.stdout for option in options), command


# ---------------------------------------------------------------------------------------------- the chain
def _command(prefix: str) -> str:
    """The README command that starts with ``prefix`` (exactly one)."""
    found = [c for c in COMMANDS if c.startswith(prefix)]
    assert len(found) == 1, (prefix, found)
    return found[0]


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder where the README's first block ran: the LPIPS weights resolved and the demo (tiny) written
    to ``runs/demo``; ``examples/`` links to the repository's."""
    from setdiff_bench.errors import WeightsError
    from setdiff_bench.metrics.lpips_arch import NETS
    from setdiff_bench.metrics.weights import load_lpips_state

    try:
        for net in NETS:
            load_lpips_state(net)
    except WeightsError:
        pytest.skip("the LPIPS weights do not resolve: the README's first command would download them")
    folder = tmp_path_factory.mktemp("readme")
    (folder / "examples").symlink_to(ROOT / "examples")
    run_example(_command("python3 -m setdiff_bench weights lpips"), folder)
    run_example(_command("python3 -m setdiff_bench demo"), folder)  # small(): --preset tiny
    return folder


def test_the_demo_wrote_what_the_readme_says(world: Path) -> None:
    """``runs/demo/`` holds the leaderboard, the lane-shift plot, the grid and the README of its stages."""
    demo = world / "runs" / "demo"
    for name in ("synthetic.md", "synthetic_lane_shift.png", "synthetic_grid.png", "README.md"):
        assert (demo / name).is_file(), name
    table = (demo / "synthetic.md").read_text(encoding="utf-8")
    for method in ("identity", "reproject", "difix", "setdiff"):
        assert f"| {method} |" in table


@pytest.mark.parametrize(
    "command", ["setdiff-bench list datasets", "setdiff-bench list methods", "setdiff-bench weights list"]
)
def test_listing_commands_run(command: str, world: Path) -> None:
    assert command in COMMANDS
    out = run_example(command, world)
    expected = {"list datasets": "synthetic", "list methods": "setdiff", "weights list": "tiny_setdiff"}
    assert expected[command.split(" ", 1)[1]] in out


def test_report_runs_on_the_demo(world: Path) -> None:
    run_example(_command("setdiff-bench report "), world)
    assert (world / "runs" / "report" / "index.html").is_file()


def test_python_api_block_runs_on_the_demo(world: Path) -> None:
    """The Python block, saved as a script and run with ``python3`` in the demo's folder (no ``exec``: the
    safe-loading scan allows none here), prints the three metric means of the store's first test packet."""
    code = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)[0]
    (world / "readme_api.py").write_text(code, encoding="utf-8")
    printed = run_shell("python3 readme_api.py", world).stdout.strip().splitlines()[-1]
    means = ast.literal_eval(printed)
    assert set(means) == {"psnr", "ssim", "lpips"}
    assert all(isinstance(value, float) for value in means.values())


def _free(port: int) -> bool:
    with socket.socket() as probe:
        try:
            probe.bind(("0.0.0.0", port))
        except OSError:
            return False
    return True


def _port_for(command: str) -> tuple[str, str]:
    """``command`` as written when port 50051 is free, else on a free port; and the client's extra words."""
    if _free(50051):
        return command, ""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    return command.replace("--port 50051", f"--port {port}"), f" --address 127.0.0.1:{port}"


def test_serve_and_drive_the_demo_packets(world: Path) -> None:
    """The service block: serve, then replay the demo's store through it; one PNG per target of the demo's
    ``run --method setdiff`` (read from that run's metrics, not from the client)."""
    serve, address = _port_for(_command("setdiff-bench serve --checkpoint tiny_setdiff --port 50051"))
    drive = _command("python3 examples/drive_packets.py --packets runs/demo/work/packets")
    with served(serve, world):
        run_shell(drive + address, world)
    targets = pd.read_parquet(world / "runs/demo/work/runs/setdiff/metrics.parquet")
    written = {(p.parent.name, p.stem) for p in (world / "enhanced").rglob("*.png")}
    assert written == {(pid, Path(frame).stem) for pid, frame in zip(targets["packet_id"], targets["frame"])}


def test_token_and_tls_serve(world: Path) -> None:
    """The token line writes a private token; ``serve`` with TLS and that token on all interfaces listens."""
    pytest.importorskip("cryptography")
    from tests.serve.serve_fixtures import make_certificates

    run_shell(_command("umask 077;"), world)
    token = (world / "token").read_text().strip()
    assert len(token) >= 32 and (os.stat(world / "token").st_mode & 0o777) == 0o600
    certificates = make_certificates(world / "certs")
    shutil.copy(certificates.server_cert, world / "server.pem")
    shutil.copy(certificates.server_key, world / "server.key")
    first = run_example(_command("setdiff-bench serve --checkpoint tiny_setdiff --host 0.0.0.0"), world)
    assert "0.0.0.0:" in first and "token" in first  # small(): on a free port (--port 0)
