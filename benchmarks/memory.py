"""Peak memory and time of enhancing one packet, and how they grow with views and resolution (issue 44).

Each case runs in its own process, so its peak resident memory (``ru_maxrss``) is its own: the process
loads the model, builds one packet of N references + M targets (smooth random images, C-maps of a
textured plane seen by cameras along a line), enhances it once and reports

* ``peak_rss_gb``: the process's peak resident memory (torch runtime + model + enhancement),
* ``above_loaded_gb``: the peak minus the memory held just before enhancing (what the packet costs),
* ``estimate_gb``: :func:`setdiff_bench.models.setdiff.memory.inference_bytes` for the same packet, and
  ``measured_over_estimate``, which the preflight check of ``run`` relies on,
* ``seconds``: the wall time of the one enhancement (the machine's load is recorded beside it).

Models: the shipped ``tiny_setdiff`` (C-map distance bias in its lowest-resolution set mixer), the paper's
plain set mixer (``benchmarks/configs/tiny_setdiff_plain.toml``, random weights: memory and time do not
depend on them) and the shipped ``tiny_difix``.

    python benchmarks/memory.py                       # the default grid (a long run on 2 cores)
    python benchmarks/memory.py --cases setdiff:8+8@576x1024 difix:8+8@576x1024
    python benchmarks/memory.py --threads 2 --out enhance_memory_cpu
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

#: ``--cases`` name → how the model is made: a shipped model, or a config file with random weights.
MODELS = {
    "setdiff": ("shipped", "tiny_setdiff"),
    "plain": ("config", str(Path(__file__).resolve().parent / "configs" / "tiny_setdiff_plain.toml")),
    "difix": ("shipped", "tiny_difix"),
}
#: The default grid: the 16-view packet at the paper's 576×1024 for each model; growth with the number of
#: views at 288×512; growth with resolution at 8 views.
DEFAULT_CASES = (
    *(f"{model}:{n}+{n}@288x512" for model in MODELS for n in (2, 4, 8, 12)),
    *(f"setdiff:4+4@{size}" for size in ("144x256", "288x512", "576x1024")),
    *(f"{model}:8+8@576x1024" for model in MODELS),
)
GB = 1 << 30


def parse_case(text: str) -> tuple[str, int, int, int, int]:
    """``setdiff:8+8@576x1024`` → ``("setdiff", 8, 8, 576, 1024)`` (height × width)."""
    model, _, rest = text.partition(":")
    views, _, size = rest.partition("@")
    references, _, targets = views.partition("+")
    height, _, width = size.partition("x")
    if model not in MODELS:
        raise SystemExit(f"memory.py: unknown model {model!r} in {text!r}; models: {', '.join(MODELS)}")
    return model, int(references), int(targets), int(height), int(width)


def plane_packet(references: int, targets: int, height: int, width: int) -> Any:
    """A packet of N + M views of a textured plane 5 units ahead, cameras 0.3 apart along x."""
    import numpy as np
    import torch

    from setdiff_bench.cameras import Camera
    from setdiff_bench.types import Packet, ViewSet

    generator = torch.Generator().manual_seed(0)

    def views(prefix: str, count: int, offset: float) -> ViewSet:
        cameras = []
        for i in range(count):
            w2c = np.eye(4)
            w2c[0, 3] = -(offset + 0.3 * i)
            focal = 0.8 * width
            K = np.array([[focal, 0, width / 2], [0, focal, height / 2], [0, 0, 1.0]])
            cameras.append(Camera(K=K, w2c=w2c, width=width, height=height))
        v, u = torch.meshgrid(torch.arange(height) + 0.5, torch.arange(width) + 0.5, indexing="ij")
        cmaps = torch.stack(
            [
                torch.stack(
                    [
                        (u - width / 2) / (0.8 * width) * 5 + offset + 0.3 * i,
                        (v - height / 2) / (0.8 * width) * 5,
                        torch.full_like(u, 5.0),
                    ]
                )
                for i in range(count)
            ]
        )
        low = torch.rand(count, 3, max(1, height // 16), max(1, width // 16), generator=generator)
        images = torch.nn.functional.interpolate(low, size=(height, width), mode="bilinear")
        return ViewSet(
            names=tuple(f"{prefix}{i}" for i in range(count)),
            images=images.contiguous(),
            cmaps=cmaps.float(),
            alphas=torch.ones(count, 1, height, width),
            cameras=tuple(cameras),
        )

    return Packet(
        packet_id="bench",
        dataset="bench",
        protocol="bench",
        group="g",
        split="test",
        scene="s",
        references=views("ref", references, 0.15),
        targets=views("tgt", targets, 0.0),
    )


def child(case: str) -> dict[str, Any]:
    """Measure one case in this process (see the module docstring)."""
    import psutil
    import torch

    from setdiff_bench.models.setdiff.checkpoint import load_model, resolve_checkpoint
    from setdiff_bench.models.setdiff.config_io import load_config
    from setdiff_bench.models.setdiff.inference import enhance_packet
    from setdiff_bench.models.setdiff.memory import inference_bytes
    from setdiff_bench.models.setdiff.model import SetDiffModel

    model_name, references, targets, height, width = parse_case(case)
    kind, source = MODELS[model_name]
    if kind == "shipped":
        model, config = load_model(
            resolve_checkpoint(source), method=model_name, device="cpu", dtype=torch.float32
        )
        model_config = config.model
    else:
        model_config = load_config(source).model
        model = SetDiffModel(model_config, load_pretrained=False).eval()
    packet = plane_packet(references, targets, height, width)
    before = psutil.Process().memory_info().rss
    start = time.perf_counter()
    enhance_packet(model, packet)
    seconds = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    estimate = inference_bytes(
        model_config, references=references, targets=targets, height=height, width=width
    )
    return {
        "case": case,
        "model": model_name,
        "references": references,
        "targets": targets,
        "height": height,
        "width": width,
        "peak_rss_gb": round(peak / GB, 3),
        "above_loaded_gb": round((peak - before) / GB, 3),
        "estimate_gb": round(estimate / GB, 3),
        "measured_over_estimate": round((peak - before) / estimate, 3),
        "seconds": round(seconds, 1),
        "load_average_1min": round(os.getloadavg()[0], 2),
    }


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--cases", nargs="+", default=list(DEFAULT_CASES), help="model:N+M@HxW ...")
    parser.add_argument("--threads", type=int, default=1, help="torch threads per case (SETDIFF_THREADS)")
    parser.add_argument("--out", default="enhance_memory_cpu", help="benchmarks/results/<OUT>.json")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.child)))
        return 0
    from benchmarks.common import machine, write_result
    from setdiff_bench.runtime.provenance import git_revision

    for case in args.cases:
        parse_case(case)
    rows = []
    environment = {**os.environ, "SETDIFF_THREADS": str(args.threads), "OMP_NUM_THREADS": str(args.threads)}
    for case in args.cases:
        done = subprocess.run(
            [sys.executable, __file__, "--child", case],
            capture_output=True,
            text=True,
            env=environment,
            check=False,
        )
        if done.returncode:
            rows.append({"case": case, "error": done.stderr.strip().splitlines()[-1:]})
        else:
            rows.append(json.loads(done.stdout.strip().splitlines()[-1]))
        print(json.dumps(rows[-1]), flush=True)
    payload = {
        "command": "python benchmarks/memory.py " + " ".join(sys.argv[1:]),
        "code": git_revision(),
        "machine": machine(),
        "threads": args.threads,
        "cases": rows,
    }
    print(f"wrote {write_result(args.out, payload)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
