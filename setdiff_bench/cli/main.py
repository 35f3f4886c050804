"""Entry point of the ``setdiff-bench`` console script.

Every :class:`~setdiff_bench.errors.SetDiffBenchError` becomes one line on stderr
(``setdiff-bench <verb>: error: <file>: <problem>``) and exit code 2, with no traceback.  So do
operating-system errors on the user's paths (``--out`` under a file, a full disk, no permission:
``OSError`` with its file name) and argparse usage errors (one line naming the argument, instead of
argparse's usage block).  Set ``SETDIFF_DEBUG=1`` to see tracebacks.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import re
import shlex
import sys
import textwrap
from collections.abc import Sequence
from types import ModuleType
from typing import NoReturn

import setdiff_bench.cli as cli_package
from setdiff_bench import __version__
from setdiff_bench.errors import SetDiffBenchError
from setdiff_bench.runtime.threads import verb_threads


def verb_modules() -> list[ModuleType]:
    """Every module in ``setdiff_bench.cli`` that defines a verb, sorted by verb name."""
    modules = []
    for info in pkgutil.iter_modules(cli_package.__path__):
        if info.name.startswith("_") or info.name == "main":
            continue
        module = importlib.import_module(f"setdiff_bench.cli.{info.name}")
        if hasattr(module, "VERB") and hasattr(module, "run"):
            modules.append(module)
    return sorted(modules, key=lambda m: m.VERB)


class OneLineArgumentParser(argparse.ArgumentParser):
    """argparse with one-line usage errors: ``setdiff-bench <verb>: error: <message> (see <prog> --help)``,
    exit code 2 — the same prefix as every other error of the verb, also for ``list`` targets.

    Sub-parsers (verbs, ``list`` targets) inherit the class through ``add_subparsers``.
    """

    def error(self, message: str) -> NoReturn:
        prefix = " ".join(self.prog.split()[:2])  # "setdiff-bench list scenes" -> "setdiff-bench list"
        self.exit(2, f"{prefix}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


class ParagraphHelpFormatter(argparse.HelpFormatter):
    """Help text from module docstrings: paragraphs are re-wrapped, indented blocks (examples) kept line
    by line, reStructuredText ``literal`` / ``Examples::`` markup shown plainly."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        text = re.sub(r":\w+:`", "`", textwrap.dedent(text).replace("``", "`").replace("::\n", ":\n"))
        blocks = []
        for paragraph in re.split(r"\n\s*\n", text.strip("\n")):
            lines = paragraph.splitlines()
            if all(line.startswith((" ", "\t")) or not line.strip() for line in lines):
                blocks.append("\n".join(indent + line.rstrip() for line in lines))
            else:
                blocks.append(
                    textwrap.fill(
                        " ".join(paragraph.split()), width, initial_indent=indent, subsequent_indent=indent
                    )
                )
        return "\n\n".join(blocks)


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineArgumentParser(
        prog="setdiff-bench",
        description="Benchmark and enhance 3D Gaussian Splatting renders far from the recorded trajectory.",
    )
    parser.add_argument("--version", action="version", version=f"setdiff-bench {__version__}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB", required=True)
    for module in verb_modules():
        verb_parser = sub.add_parser(
            module.VERB,
            help=module.HELP,
            description=getattr(module, "DESCRIPTION", module.HELP),
            formatter_class=ParagraphHelpFormatter,
        )
        module.add_arguments(verb_parser)
        verb_parser.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv`` and run the verb; returns the process exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    #: the command as typed, for the records a verb writes (training manifests)
    args.command_line = "setdiff-bench " + shlex.join(sys.argv[1:] if argv is None else list(argv))
    try:
        with verb_threads():  # one fixed thread count: same command, same machine, same bytes
            return int(args._run(args) or 0)
    except SetDiffBenchError as error:
        if os.environ.get("SETDIFF_DEBUG"):
            raise
        print(f"setdiff-bench {args.verb}: error: {error.one_line()}", file=sys.stderr)
        return 2
    except OSError as error:  # the user's paths: --out under a file, disk full, permission denied
        if os.environ.get("SETDIFF_DEBUG"):
            raise
        where = f"{error.filename}: " if error.filename else ""
        print(f"setdiff-bench {args.verb}: error: {where}{error.strerror or error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as interrupt:  # Interrupted says where the work was saved
        detail = f" ({interrupt})" if str(interrupt) else ""
        print(f"setdiff-bench {args.verb}: interrupted{detail}", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
