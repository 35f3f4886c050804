"""The FID Inception-v3 read from a local state dict: keys, shapes, bad files, features (issue 41).

No real weights are downloaded: a random-weight network of the same architecture is saved in the
pytorch-fid format (a ``torch.save``d state dict) and read back.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from setdiff_bench.errors import WeightsError
from setdiff_bench.metrics.inception import FIDInceptionV3, inception_features, load_inception
from setdiff_bench.runtime.threads import torch_threads
from tests.metrics.inception_fixtures import random_inception, save_inception


@pytest.fixture(scope="module")
def random_weights(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, FIDInceptionV3]:
    model = random_inception()
    with torch_threads(1), torch.no_grad():
        for module in model.modules():  # non-trivial batch-norm statistics, so loading them is tested
            if isinstance(module, torch.nn.BatchNorm2d):
                module.running_mean.uniform_(-0.1, 0.1)
                module.running_var.uniform_(0.5, 1.5)
    return save_inception(model, tmp_path_factory.mktemp("inception")), model


def test_architecture_has_torchvisions_inception3_parameter_count() -> None:
    # torchvision's Inception3(aux_logits=False) has 23 834 568 parameters with 1000 classes;
    # the FID port's classifier has 1008: 8 more rows of 2048 weights + 1 bias each
    count = sum(p.numel() for p in FIDInceptionV3().parameters())
    assert count == 23_834_568 + 8 * 2049


def test_loaded_network_gives_the_saved_networks_features(random_weights) -> None:
    path, model = random_weights
    with torch_threads(1):
        loaded = load_inception(path)
        images = torch.rand(2, 3, 40, 56, generator=torch.Generator().manual_seed(3))
        with torch.no_grad():
            expected = model(images)
        features = inception_features(loaded, list(images), batch_size=2)
    assert features.shape == (2, 2048) and features.dtype == np.float64
    assert np.array_equal(features, expected.double().numpy())
    # features well above zero, and different for different images: the equality above is not vacuous
    assert np.abs(features).mean() > 1e-2
    assert np.abs(features[0] - features[1]).mean() > 1e-3


def test_state_dict_without_num_batches_tracked_loads(random_weights, tmp_path: Path) -> None:
    path, _ = random_weights
    state = {k: v for k, v in torch.load(path, weights_only=True).items() if "num_batches_tracked" not in k}
    torch.save(state, tmp_path / "old.pth")
    assert isinstance(load_inception(tmp_path / "old.pth"), FIDInceptionV3)


def _refusal(path: Path) -> str:
    with pytest.raises(WeightsError) as info:
        load_inception(path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(str(path))
    return message


def test_bad_files_are_one_line_naming_the_file(random_weights, tmp_path: Path) -> None:
    path, _ = random_weights
    assert "Inception weights file not found (pass --inception FILE" in _refusal(tmp_path / "absent.pth")
    (tmp_path / "text.pth").write_text("not a checkpoint")
    assert "not a PyTorch state dict" in _refusal(tmp_path / "text.pth")
    state = torch.load(path, weights_only=True)

    def save(name: str, data: object) -> Path:
        torch.save(data, tmp_path / name)
        return tmp_path / name

    assert "tensors missing (first 'Conv2d_1a_3x3.bn.bias')" in _refusal(
        save("missing.pth", {k: v for k, v in state.items() if k != "Conv2d_1a_3x3.bn.bias"})
    )
    aux = {**state, "AuxLogits.conv0.conv.weight": torch.zeros(128, 768, 1, 1)}
    assert "unexpected tensor 'AuxLogits.conv0.conv.weight'" in _refusal(save("aux.pth", aux))
    wrong = {**state, "fc.weight": torch.zeros(1000, 2048)}
    assert "'fc.weight' has shape (1000, 2048), the FID Inception-v3 has (1008, 2048)" in _refusal(
        save("classes.pth", wrong)
    )
    nan = {**state, "Mixed_7c.branch_pool.bn.running_var": torch.full((192,), float("nan"))}
    assert "NaN" in _refusal(save("nan.pth", nan))
    assert "expected a state dict" in _refusal(save("list.pth", [1, 2, 3]))


def test_features_of_a_stand_in_network_batch_by_size() -> None:
    class Means(torch.nn.Module):  # (B, 3, H, W) -> (B, 3): channel means, a hand-checkable "network"
        def __init__(self) -> None:
            super().__init__()
            self.calls: list[int] = []

        def forward(self, x: torch.Tensor) -> torch.Tensor:
            self.calls.append(x.shape[0])
            return x.mean(dim=(2, 3))

    net = Means()
    images = [torch.full((3, 4, 4), v) for v in (0.1, 0.2, 0.3)] + [torch.full((3, 2, 6), 0.5)]
    features = inception_features(net, images, batch_size=2)
    assert np.allclose(features, [[0.1] * 3, [0.2] * 3, [0.3] * 3, [0.5] * 3])
    assert net.calls == [2, 1, 1]  # two of 4x4, one of 4x4, then the other size alone
