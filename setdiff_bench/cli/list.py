"""``setdiff-bench list <target>``: list what the toolkit can see.

Targets are entries of :data:`TARGETS` (one subcommand each); a new target adds a
:class:`ListTarget` there.  Built in:

* ``list datasets``: the dataset keys the loaders know.
* ``list methods``: the enhancers ``setdiff-bench run --method`` accepts (built-ins and entry-point
  plugins), with a one-line description and whether each needs weights or a GPU; nothing heavy is
  imported to list them.
* ``list scenes --dataset D --root R``: load every scene (validating poses, images and masks) and
  print one row per scene with frame, camera (distinct sensors) and traversal counts, the dataset's
  train/test designation and the image sizes; ``--names-only`` lists names without loading.
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from setdiff_bench.cli import add_option_argument, parse_option

VERB = "list"
HELP = "list datasets, methods, or the scenes of a dataset on disk"
DESCRIPTION = (
    "List what the toolkit can see: `list datasets`, `list methods`, `list scenes --dataset D --root R`.\n\n"
    "Examples:\n\n    setdiff-bench list datasets\n    setdiff-bench list methods\n"
    "    setdiff-bench list scenes --dataset synthetic --root runs/demo/work/scenes"
)


@dataclass(frozen=True)
class ListTarget:
    """One ``list`` subcommand: its help line, argument setup and runner (returns the exit code)."""

    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]


# ---------------------------------------------------------------------- list datasets
def _datasets_arguments(parser: argparse.ArgumentParser) -> None:
    del parser


def _datasets_run(args: argparse.Namespace) -> int:
    del args
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    from setdiff_bench.loaders import DATASETS

    width = max(len(key) for key in DATASETS)
    for key, spec in DATASETS.items():
        print(f"{key:<{width}}  {spec.description}")
    return 0


# ---------------------------------------------------------------------- list methods
def _methods_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="one JSON object per method instead of a table")


def _methods_run(args: argparse.Namespace) -> int:
    from setdiff_bench.enhancers.base import available_methods

    methods = available_methods()
    if args.json:
        for spec in methods.values():
            print(
                json.dumps(
                    {
                        "name": spec.name,
                        "description": spec.description,
                        "needs_weights": spec.needs_weights,
                        "needs_gpu": spec.needs_gpu,
                        "source": spec.source,
                    },
                    sort_keys=True,
                )
            )
        return 0
    headers = ["METHOD", "WEIGHTS", "GPU", "DESCRIPTION"]
    table = [
        [
            spec.name,
            "yes" if spec.needs_weights else "no",
            "yes" if spec.needs_gpu else "no",
            spec.description if spec.source == "builtin" else f"{spec.description} [plugin: {spec.source}]",
        ]
        for spec in methods.values()
    ]
    widths = [max(len(h), *(len(r[i]) for r in table)) for i, h in enumerate(headers)]
    for line in [headers, *table]:
        print("  ".join(cell.ljust(widths[i]) for i, cell in enumerate(line[:-1])) + "  " + line[-1])
    return 0


# ---------------------------------------------------------------------- list scenes
#: The loader-option flag's spellings, the same on every verb that reads a dataset (``list scenes``, ``fit``,
#: ``prepare``): ``-o KEY=VALUE`` or ``--loader-option KEY=VALUE`` (``--option``: an older name, hidden).
LOADER_OPTION_FLAGS = ("-o", "--loader-option")


def add_loader_option_argument(parser: argparse.ArgumentParser, examples: str) -> None:
    """The repeatable loader-option flag (:data:`LOADER_OPTION_FLAGS`, ``args.loader_option``); ``examples``
    shows typical values, e.g. ``"e.g. -o missing=skip"``.  Read it with :func:`loader_options`."""
    add_option_argument(
        parser,
        f"loader option, value parsed as JSON when valid ({examples}); repeatable",
        LOADER_OPTION_FLAGS,
    )
    parser.add_argument("--option", dest="loader_option", action="append", help=argparse.SUPPRESS)


def loader_options(args: argparse.Namespace, flags: tuple[str, ...] = LOADER_OPTION_FLAGS) -> dict[str, Any]:
    """``{key: value}`` of the loader-option flags given (:func:`parse_option`; a malformed one names ``flags``,
    the spellings the verb declared)."""
    return dict(parse_option(text, "/".join(flags)) for text in args.loader_option)


def _scenes_arguments(parser: argparse.ArgumentParser) -> None:
    from setdiff_bench.loaders import DATASETS

    parser.add_argument("--dataset", required=True, choices=list(DATASETS), help="dataset key")
    parser.add_argument("--root", required=True, help="dataset folder as downloaded (see docs/datasets.md)")
    parser.add_argument(
        "--scene",
        action="append",
        dest="scenes",
        metavar="NAME",
        help="only this scene (repeatable); default all",
    )
    add_loader_option_argument(parser, "e.g. -o level=1, -o version=v1.0-mini")
    parser.add_argument("--names-only", action="store_true", help="print scene names without loading them")
    parser.add_argument("--json", action="store_true", help="one JSON object per scene instead of a table")


def _scenes_run(args: argparse.Namespace) -> int:
    from setdiff_bench.loaders import list_scenes, load_scenes

    options = loader_options(args)
    if args.names_only:
        names = list_scenes(args.dataset, args.root, **options)
        if args.scenes:
            from setdiff_bench.loaders.common import select_scenes

            names = select_scenes(names, args.scenes, args.root, args.dataset)
        for name in names:
            print(json.dumps({"scene": name}) if args.json else name)
        return 0
    scenes = load_scenes(args.dataset, args.root, args.scenes, **options)
    rows = [_summary(scene) for scene in scenes]
    if args.json:
        for row in rows:
            print(json.dumps(row, sort_keys=True))
        return 0
    headers = ["SCENE", "FRAMES", "CAMERAS", "TRAVERSALS", "TRAIN", "TEST", "SIZE"]
    table = [
        [
            row["scene"],
            str(row["frames"]),
            str(row["cameras"]),
            str(row["traversals"]),
            _count(row["train"]),
            _count(row["test"]),
            ",".join(row["sizes"]),
        ]
        for row in rows
    ]
    widths = [max(len(h), *(len(r[i]) for r in table)) if table else len(h) for i, h in enumerate(headers)]
    print(f"{args.dataset}: {len(rows)} scene{'s' if len(rows) != 1 else ''} under {args.root}")
    for line in [headers, *table]:
        print(
            "  ".join(
                cell.ljust(widths[i]) if i == 0 else cell.rjust(widths[i]) for i, cell in enumerate(line)
            )
        )
    return 0


def _count(value: int | None) -> str:
    return "-" if value is None else str(value)


def _summary(scene: Any) -> dict[str, Any]:
    """Counts printed for one scene; ``train``/``test`` are ``None`` where the dataset defines no split."""
    splits = Counter(frame.split for frame in scene.frames)
    has_split = any(split is not None for split in splits)
    sizes = Counter(f"{frame.camera.width}x{frame.camera.height}" for frame in scene.frames)
    return {
        "scene": scene.name,
        "frames": len(scene.frames),
        "cameras": len(scene.sensors),
        "traversals": len(scene.traversals),
        "train": splits.get("train", 0) if has_split else None,
        "test": splits.get("test", 0) if has_split else None,
        "sizes": [size for size, _ in sizes.most_common()],
    }


TARGETS: dict[str, ListTarget] = {
    "datasets": ListTarget("dataset keys known to the loaders", _datasets_arguments, _datasets_run),
    "methods": ListTarget(
        "enhancers for `run --method` (built-in and plugins)", _methods_arguments, _methods_run
    ),
    "scenes": ListTarget(
        "scenes of a dataset on disk, with frame and camera counts", _scenes_arguments, _scenes_run
    ),
}

#: The example each target's ``--help`` shows (also listed in ``list --help``).
TARGET_EXAMPLES = {
    "datasets": "setdiff-bench list datasets",
    "methods": "setdiff-bench list methods",
    "scenes": "setdiff-bench list scenes --dataset synthetic --root runs/demo/work/scenes",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """One subcommand per entry of :data:`TARGETS`."""
    sub = parser.add_subparsers(dest="target", metavar="TARGET", required=True)
    for name, target in TARGETS.items():
        description = target.help[0].upper() + target.help[1:] + "."
        description += f"\n\nExample:\n\n    {TARGET_EXAMPLES[name]}" if name in TARGET_EXAMPLES else ""
        target_parser = sub.add_parser(
            name,
            help=target.help,
            description=description,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        target.add_arguments(target_parser)
        target_parser.set_defaults(_list_target=target)


def run(args: argparse.Namespace) -> int:
    return args._list_target.run(args)
