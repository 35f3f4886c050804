"""The demo's test scenes: how the preset's benchmark names its scenes, how many it holds, which of them the
benchmark protocol's split makes test scenes, and the check that no shipped model was trained on one."""

from __future__ import annotations

from typing import Any

from setdiff_bench.errors import UsageError
from setdiff_bench.models.setdiff.packaged import packaged_models
from setdiff_bench.pipeline.presets import DemoPreset, get_benchmark
from setdiff_bench.protocols import load_protocol
from setdiff_bench.synthetic.kinds import scene_kind_of

#: The learned methods and the shipped models the driving demo evaluates unless ``--train``.
SHIPPED_MODELS = get_benchmark("driving").shipped


def scene_namer(preset: DemoPreset) -> Any:
    """``(seed, index) → scene name`` as ``synth`` names the preset's scenes (its scene kind's names)."""
    return scene_kind_of(preset.synth_preset).scene_name


def scene_count(preset: DemoPreset) -> int:
    """How many scenes (indices ``0 … count - 1``) the preset's benchmark holds."""
    if preset.scenes:
        return preset.scenes
    kind = scene_kind_of(preset.synth_preset)
    return kind.get_preset(preset.synth_preset).num_scenes


def evaluation_scene_indices(preset: DemoPreset, seed: int) -> list[int]:
    """The generator indices of the preset's test scenes: the benchmark protocol's scene split over the
    scene names ``synth`` gives the preset's scenes.

    Raises:
        UsageError: no scene of ``seed`` is a test scene (the sparse protocol lists seed 0's).
    """
    benchmark = get_benchmark(preset.benchmark)
    name = scene_namer(preset)
    names = [name(seed, index) for index in range(scene_count(preset))]
    assignment = load_protocol(benchmark.protocol or benchmark.dataset).split.assign(names)
    indices = [index for index, name in enumerate(names) if assignment[name] == "test"]
    if not indices:
        raise UsageError(
            f"the {benchmark.name} benchmark's protocol has no test scene among seed {seed}'s scenes "
            f"({names[0]} …); its test scenes are listed in protocol {benchmark.protocol}",
            "--seed",
        )
    return indices


def check_unseen(
    test_scenes: list[tuple[int, int]],
    shipped_models: dict[str, str] | None = None,
    scene_name: Any = None,
) -> dict[str, dict[str, Any]]:
    """The shipped models' manifests, after checking that none was trained on a demo test scene.

    Args:
        test_scenes: ``(seed, index)`` of each test scene.
        shipped_models: ``{method: packaged model}`` (default: the driving benchmark's).
        scene_name: ``(seed, index) → scene name`` of the benchmark's scenes (default: the driving
            benchmark's, :func:`setdiff_bench.synthetic.generate.scene_name`); compared with the training
            scene names in each manifest (``data.scenes``), so a driving scene and a sparse walk of the same
            ``(seed, index)`` are different scenes.

    Raises:
        UsageError: a shipped model is missing, or its training scenes include a test scene.
    """
    if scene_name is None:
        from setdiff_bench.synthetic.generate import scene_name
    tested = {scene_name(seed, index) for seed, index in test_scenes}
    shipped = packaged_models()
    manifests = {}
    for method, name in (SHIPPED_MODELS if shipped_models is None else shipped_models).items():
        if name not in shipped:
            raise UsageError(
                f"the shipped model {name!r} is not in this installation; run the demo with --train",
                "--train",
            )
        manifest = shipped[name].manifest
        seen = tested & {str(scene).rsplit("/", 1)[-1] for scene in manifest["data"]["scenes"]}
        if seen:
            raise UsageError(
                f"shipped model {name!r} was trained on scene {sorted(seen)[0]}, one of "
                "this demo's test scenes: pick another --seed or use --train",
                "--seed",
            )
        manifests[method] = manifest
    return manifests
