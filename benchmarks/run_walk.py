"""How far ``setdiff-bench run``'s arguments travel: the files its settings pass through from the CLI to scoring.

    python benchmarks/run_walk.py --packets STORE [--method identity] [--shard 0/8]

Runs the ``run`` verb in this process under ``sys.setprofile`` and records, for the toolkit's own code:

* **settings walk**: every function called with the verb's parsed arguments (the ``argparse.Namespace``), the
  :class:`~setdiff_bench.evaluation.run.RunSettings` made from them, or one of their path fields (the same
  ``Path`` object) as an argument: its (file, function) pairs
  ("stays", each counted once however many packets repeat it) and the files they sit in;
* **stack to scoring**: the toolkit files on the call stack each time a metric of ``setdiff_bench.metrics``
  is computed (the path from ``cli.main`` to the score), their union and the longest single stack.

Files are named relative to the package; ``loaders/`` and ``protocols/`` as installed.  Writes
``benchmarks/results/run_walk.json``.  No library measures an import-free call walk of one verb, so this is
written here; it uses only the standard profiler hook.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path
from types import FrameType
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.common import write_result


def _own_file(path: str, roots: list[Path]) -> str | None:
    """``path`` relative to the package (``evaluation/run/_method.py``), or None outside the toolkit."""
    resolved = Path(path)
    for root in roots:
        if resolved.is_relative_to(root):
            return str(resolved.relative_to(root.parent if root.name != "setdiff_bench" else root))
    return None


def walk(argv: list[str]) -> dict[str, Any]:
    """Run ``setdiff-bench <argv>`` under the profiler; the settings walk and the stacks to scoring."""
    import setdiff_bench
    from setdiff_bench.cli.main import main
    from setdiff_bench.evaluation.run import RunSettings

    repo = Path(setdiff_bench.__file__).resolve().parents[1]
    roots = [Path(setdiff_bench.__file__).resolve().parent, repo / "loaders", repo / "protocols"]
    stays: dict[tuple[str, str], int] = {}
    stacks: list[list[str]] = []
    cache: dict[str, str | None] = {}

    def own(code_file: str) -> str | None:
        if code_file not in cache:
            cache[code_file] = _own_file(code_file, roots)
        return cache[code_file]

    carried: dict[int, object] = {}  # id -> the settings objects and their path-valued fields, kept alive

    def carries_settings(frame: FrameType) -> bool:
        code = frame.f_code
        count = code.co_argcount + code.co_kwonlyargcount
        found = False
        for name in code.co_varnames[:count]:
            value = frame.f_locals.get(name)
            if isinstance(value, argparse.Namespace | RunSettings):
                for field in vars(value).values():
                    if isinstance(field, Path):
                        carried[id(field)] = field
                carried[id(value)] = value
                found = True
            elif id(value) in carried:
                found = True
        return found

    def profile(frame: FrameType, event: str, _arg: Any) -> None:
        if event != "call":
            return
        file = own(frame.f_code.co_filename)
        if file is None:
            return
        if carries_settings(frame):
            key = (file, frame.f_code.co_qualname)
            stays[key] = stays.get(key, 0) + 1
        if file.startswith("metrics/"):
            stack, outer = [], frame
            while outer is not None:
                outer_file = own(outer.f_code.co_filename)
                if outer_file is not None and outer_file not in stack:
                    stack.append(outer_file)
                outer = outer.f_back
            stacks.append(stack)

    sys.setprofile(profile)
    try:
        code = main(argv)
    finally:
        sys.setprofile(None)
    if code != 0:
        raise SystemExit(f"run_walk: setdiff-bench {' '.join(argv)} exited {code}")
    walk_files = sorted({file for file, _ in stays})
    union = sorted({file for stack in stacks for file in stack})
    longest = max(stacks, key=len) if stacks else []
    return {
        "settings_walk": {
            "stays": len(stays),
            "files": len(walk_files),
            "file_list": walk_files,
            "functions": [f"{file}:{name}" for file, name in sorted(stays)],
        },
        "stack_to_scoring": {
            "metric_calls": len(stacks),
            "files_in_any_stack": len(union),
            "file_list": union,
            "longest_stack_files": len(longest),
            "longest_stack": list(reversed(longest)),
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--packets", required=True, type=Path, help="packet store (setdiff-bench prepare)")
    parser.add_argument("--method", default="identity", help="method to run (default identity)")
    parser.add_argument("--shard", default="0/8", help="run's --shard, to keep the walk short (default 0/8)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as out:
        argv = ["run", "--method", args.method, "--packets", str(args.packets), "--split", "test"]
        argv += ["--shard", args.shard, "--out", str(Path(out) / "run"), "--no-progress"]
        result = walk(argv)
    command = f"python benchmarks/run_walk.py --packets STORE --method {args.method} --shard {args.shard}"
    payload = {"command": command, **result}
    path = write_result("run_walk", payload)
    print(json.dumps({k: v for k, v in result["settings_walk"].items() if k != "functions"}, indent=1))
    print(json.dumps({k: v for k, v in result["stack_to_scoring"].items()}, indent=1))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
