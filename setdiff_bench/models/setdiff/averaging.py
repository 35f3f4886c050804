"""Post-hoc weight averaging: one model whose weights are the uniform mean of a training run's last saved
checkpoints (the idea of stochastic weight averaging, applied to the checkpoints a finished run kept).

Why: two training seeds of the same tiny SetDiff recipe differ most on frames that need no repair (held-out
renders), where a checkpoint's step-to-step noise shows as damage; averaging the run's last checkpoints
(same trajectory, constant learning rate) smooths that noise without another training run (measured in
``docs/model_recipe.md`` and ``benchmarks/results/weight_averaging.json``).

Written here, not with ``torch.optim.swa_utils.AveragedModel``: that class averages a live model during
training, whereas this reads the finished run's ``model.safetensors`` files from disk.  Floating-point
tensors are averaged in float64 and stored in their own dtype; every other tensor (integer buffers) must be
equal in all checkpoints.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import torch

from setdiff_bench.errors import CheckpointError, UsageError
from setdiff_bench.models.setdiff.checkpoint import check_compatible, read_config, saved_step
from setdiff_bench.models.setdiff.files import CHECKPOINTS_DIR, WEIGHTS_FILE


def check_average_count(count: int, where: str) -> int:
    """``count`` checkpoints to average (at least 2: one is no average), else UsageError naming ``where``."""
    if count < 2:
        raise UsageError(f"--average must be 2 or more checkpoints, got {count}", where)
    return count


def run_checkpoints(run: Path) -> list[tuple[int, Path]]:
    """A training run's kept checkpoints as ``(step, folder)``, oldest first.

    Raises:
        CheckpointError: the run has no ``checkpoints/`` folder with a step folder in it.
    """
    folders = [f for f in sorted((run / CHECKPOINTS_DIR).glob("step-*")) if (f / WEIGHTS_FILE).is_file()]
    if not folders:
        raise CheckpointError(f"no checkpoints in {CHECKPOINTS_DIR}/ (is it a training run folder?)", run)
    return sorted((saved_step(folder), folder) for folder in folders)


def average_weights(checkpoints: Sequence[Path]) -> dict[str, torch.Tensor]:
    """The uniform mean of the checkpoints' weights (same architecture, same parameter names and shapes).

    Args:
        checkpoints: checkpoint folders, each with ``config.json`` and ``model.safetensors``.

    Returns:
        ``{name: tensor}`` on the CPU, each in its checkpoints' dtype.

    Raises:
        CheckpointError: no checkpoint given, or they differ in architecture, parameter names, shapes,
            dtypes or a non-float tensor.
    """
    from safetensors.torch import load_file

    if not checkpoints:
        raise CheckpointError("nothing to average", "averaging")
    first = read_config(checkpoints[0])
    reference = load_file(str(checkpoints[0] / WEIGHTS_FILE))
    sums = {name: t.double() for name, t in reference.items() if t.is_floating_point()}
    for folder in checkpoints[1:]:
        check_compatible(read_config(folder), first, folder)
        state = load_file(str(folder / WEIGHTS_FILE))
        if set(state) != set(reference):
            raise CheckpointError("weights have other parameter names than the first checkpoint's", folder)
        for name, tensor in state.items():
            expected = reference[name]
            if tensor.shape != expected.shape or tensor.dtype != expected.dtype:
                raise CheckpointError(f"weight {name} differs in shape or dtype from the first's", folder)
            if name in sums:
                sums[name] += tensor.double()
            elif not torch.equal(tensor, expected):
                raise CheckpointError(f"non-float tensor {name} differs between checkpoints", folder)
    return {
        name: (sums[name] / len(checkpoints)).to(tensor.dtype) if name in sums else tensor
        for name, tensor in reference.items()
    }
