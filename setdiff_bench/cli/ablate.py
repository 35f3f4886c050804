"""``setdiff-bench ablate geometry|setsize``: the paper's Tables 5 and 6 on a packet store.

    setdiff-bench ablate geometry --packets P --out DIR [--config tiny_setdiff] [--steps N] [--seed S ...]
                                  [--variants none,cmap,pose,both] [--average K] [--guidance-scale G]
    setdiff-bench ablate setsize --packets P --checkpoint CKPT [--checkpoint CKPT ...] --out DIR
                                 [--sizes 1+1,2+1,3+1,3+2,3+4,3+6] [--guidance-scale G]

``geometry`` trains four SetDiff variants (no geometry, C-maps only, camera poses only, both) with
the same config, seed and steps, and runs each on the test packets (``--variants none,both`` keeps the
paper's main comparison at two trainings per seed instead of four); ``setsize`` runs one trained
SetDiff at several N + M set sizes.  Repeating ``--seed`` (geometry: every variant is trained once
per seed) or ``--checkpoint`` (set size: one model per training seed) makes each cell the mean over
the models, with the spread under the table and each model's values in ``*_per_model.parquet``.
``--guidance-scale`` runs every model at that geometry CFG scale instead of its checkpoint's own (an
inference setting, so the trained models are reused; its runs go to ``runs/cfg<G>/``).  ``geometry
--average K`` runs, for every trained variant, the uniform mean of its K newest checkpoints (a ``weights
export --average K`` stage into ``averaged<K>/``; runs in ``runs/avg<K>/``).
Every stage is an ordinary ``setdiff-bench`` command (listed in the output tables) and resumes, so an
interrupted ablation continues where it stopped.  Tables go to ``<out>/ablation_geometry.{md,tex,parquet}``
and ``<out>/ablation_setsize.{md,tex,parquet}``; checkpoints and runs to ``--work`` (default ``<out>/work``).

The examples use the packets of ``setdiff-bench demo --train``, which have the ``train`` split that
``geometry`` needs.  Examples::

    setdiff-bench ablate geometry --packets runs/demo/work/packets --out runs/ablation --variants none,both --steps 200
    setdiff-bench ablate setsize --packets runs/demo/work/packets --checkpoint tiny_setdiff --out runs/ablation \\
        --sizes 1+1,3+1
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from setdiff_bench.cli import add_device_argument, add_progress_argument
from setdiff_bench.pipeline.ablation import DEFAULT_SIZES

VERB = "ablate"
HELP = "the paper's ablations: geometric grounding (Table 5) and set size (Table 6)"
DESCRIPTION = __doc__.split("\n\n", 1)[1] if __doc__ else HELP


def _with_examples(summary: str, prefix: str) -> str:
    """``summary`` and, under ``Examples:``, the examples of the module docstring that start with ``prefix``
    (a study's own ``--help`` shows its examples, written once)."""
    block = (__doc__ or "").split("Examples", 1)[-1].split("::", 1)[-1]
    examples: list[list[str]] = []
    for line in block.splitlines():
        if line.strip().startswith("setdiff-bench "):
            examples.append([line.rstrip()])
        elif line.strip() and examples and examples[-1][-1].endswith("\\"):
            examples[-1].append(line.rstrip())  # a continued line
    kept = ["\n".join(lines) for lines in examples if lines[0].strip().startswith(prefix)]
    return summary[0].upper() + summary[1:] + "." + ("\n\nExamples:\n\n" + "\n".join(kept) if kept else "")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="study", metavar="STUDY", required=True)
    geometry_help = "train and score SetDiff without / with C-maps / poses / both"
    geometry = sub.add_parser(
        "geometry",
        help=geometry_help,
        description=_with_examples(geometry_help, "setdiff-bench ablate geometry"),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    geometry.add_argument(
        "--config", default="tiny_setdiff", help="base SetDiff config (TOML or packaged name)"
    )
    geometry.add_argument(
        "--steps", type=int, default=None, help="training steps per variant (default: the config's)"
    )
    geometry.add_argument(
        "--seed",
        type=int,
        action="append",
        default=None,
        help="training seed (default: the config's); repeat to train every variant once per seed",
    )
    geometry.add_argument(
        "--average",
        type=int,
        metavar="K",
        help="run each variant as the mean of its K newest checkpoints (weights export --average K)",
    )
    geometry.add_argument(
        "--variants",
        default=None,
        help="comma list of the variants to train (default: all four; keys none, cmap, pose, both)",
    )
    setsize_help = "score one trained SetDiff at several reference + target set sizes"
    setsize = sub.add_parser(
        "setsize",
        help=setsize_help,
        description=_with_examples(setsize_help, "setdiff-bench ablate setsize"),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    setsize.add_argument(
        "--checkpoint",
        required=True,
        type=Path,
        action="append",
        help="trained SetDiff (setdiff-bench train --out); repeat for models of other training seeds",
    )
    setsize.add_argument("--sizes", default=DEFAULT_SIZES, help="comma list of N+M set sizes")
    for study in (geometry, setsize):
        study.add_argument("--packets", required=True, type=Path, help="packet store (setdiff-bench prepare)")
        study.add_argument("--out", required=True, type=Path, help="folder for the ablation tables")
        study.add_argument(
            "--work", type=Path, default=None, help="checkpoints and runs (default: <out>/work)"
        )
        study.add_argument(
            "--guidance-scale",
            type=float,
            metavar="G",
            help="geometry CFG scale of every run (default: each checkpoint's own)",
        )
        add_device_argument(study, "where training and inference run")
        add_progress_argument(study)


def run(args: argparse.Namespace) -> int:
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    from setdiff_bench.models.setdiff.averaging import check_average_count
    from setdiff_bench.models.setdiff.config import check_guidance_scale
    from setdiff_bench.pipeline.ablation import AblationSettings, run_ablation
    from setdiff_bench.pipeline.stages import StageFailed
    from setdiff_bench.runtime.devices import resolve_device

    resolve_device(
        args.device
    )  # checked here; passed on as given (auto: not at all), so the stages resolve it
    if args.guidance_scale is not None:
        check_guidance_scale(args.guidance_scale, "--guidance-scale")
    if getattr(args, "average", None) is not None:
        check_average_count(args.average, "--average")
    fields = {field.name for field in dataclasses.fields(AblationSettings)}
    given = {name: value for name, value in vars(args).items() if name in fields}  # this study's flags
    for name in ("seed", "checkpoint"):  # repeated flags: tuples in the frozen settings
        if given.get(name) is not None:
            given[name] = tuple(given[name])
    try:
        paths = run_ablation(AblationSettings(**given))
    except StageFailed as failure:
        return failure.code
    for path in paths.values():
        print(f"wrote {path}")
    return 0
