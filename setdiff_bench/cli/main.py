"""Entry point of the ``setdiff-bench`` console script.

Every :class:`~setdiff_bench.errors.SetDiffBenchError` becomes one line on stderr
(``setdiff-bench <verb>: error: <file>: <problem>``) and exit code 2, with no traceback; an error that names
the library parameter at fault is printed with the verb's option for it instead (``--checkpoint nope:
checkpoint not found ...``, :func:`parameter_options`).  So do
operating-system errors on the user's paths (``--out`` under a file, a full disk, no permission:
``OSError`` with its file name) and argparse usage errors (one line naming the argument, instead of
argparse's usage block).  Set ``SETDIFF_DEBUG=1`` to see tracebacks.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import importlib
import os
import pkgutil
import re
import shlex
import sys
import textwrap
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import ModuleType
from typing import NoReturn

import setdiff_bench.cli as cli_package
from setdiff_bench.errors import SetDiffBenchError
from setdiff_bench.runtime.threads import verb_threads
from setdiff_bench.version import __version__


def verb_module_names() -> list[str]:
    """The names of the modules in ``setdiff_bench.cli`` that may define a verb (none is imported)."""
    return sorted(
        info.name
        for info in pkgutil.iter_modules(cli_package.__path__)
        if not info.name.startswith("_") and info.name != "main"
    )


def verb_modules() -> list[ModuleType]:
    """Every module in ``setdiff_bench.cli`` that defines a verb, sorted by verb name."""
    modules = [importlib.import_module(f"setdiff_bench.cli.{name}") for name in verb_module_names()]
    return sorted((m for m in modules if hasattr(m, "VERB") and hasattr(m, "run")), key=lambda m: m.VERB)


def verb_summaries() -> dict[str, str]:
    """``{VERB: HELP}`` of every verb module, read from its source without importing it (a verb module may
    import a heavy dependency at module level; listing the verbs must not).

    A module whose ``VERB`` and ``HELP`` are not plain string literals is imported instead.
    """
    summaries = {}
    for name in verb_module_names():
        path = Path(cli_package.__path__[0]) / f"{name}.py"
        constants: dict[str, str] = {}
        try:
            tree = ast.parse(path.read_text(encoding="utf-8"))
        except (OSError, SyntaxError, UnicodeDecodeError):
            tree = ast.Module(body=[], type_ignores=[])
        for node in tree.body:
            if isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant):
                for target in node.targets:
                    if isinstance(target, ast.Name) and isinstance(node.value.value, str):
                        constants[target.id] = node.value.value
        has_run = any(isinstance(node, ast.FunctionDef) and node.name == "run" for node in tree.body)
        if "VERB" in constants and "HELP" in constants and has_run:
            summaries[constants["VERB"]] = constants["HELP"]
            continue
        module = importlib.import_module(f"setdiff_bench.cli.{name}")
        if hasattr(module, "VERB") and hasattr(module, "run"):
            summaries[module.VERB] = module.HELP
    return dict(sorted(summaries.items()))


class OneLineArgumentParser(argparse.ArgumentParser):
    """argparse with one-line usage errors: ``setdiff-bench <verb>: error: <message> (see <prog> --help)``,
    exit code 2 — the same prefix as every other error of the verb, also for ``list`` targets.

    Sub-parsers (verbs, ``list`` targets) inherit the class through ``add_subparsers``.
    """

    def error(self, message: str) -> NoReturn:
        prefix = " ".join(self.prog.split()[:2])  # "setdiff-bench list scenes" -> "setdiff-bench list"
        self.exit(2, f"{prefix}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


class ParagraphHelpFormatter(argparse.HelpFormatter):
    """Help text from module docstrings: paragraphs are re-wrapped, indented blocks (examples, also under a
    one-line heading such as ``examples:``) kept line by line, reStructuredText ``literal`` /
    ``Examples::`` markup shown plainly."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        text = re.sub(r":\w+:`", "`", textwrap.dedent(text).replace("``", "`").replace("::\n", ":\n"))
        blocks = []
        for paragraph in re.split(r"\n\s*\n", text.strip("\n")):
            lines = paragraph.splitlines()
            # an indented block, possibly under a one-line heading ("examples:"), is kept line by line
            body = lines[1:] if len(lines) > 1 and lines[0].rstrip().endswith(":") else lines
            if all(line.startswith((" ", "\t")) or not line.strip() for line in body):
                blocks.append("\n".join(indent + line.rstrip() for line in lines))
            else:
                blocks.append(
                    textwrap.fill(
                        " ".join(paragraph.split()), width, initial_indent=indent, subsequent_indent=indent
                    )
                )
        return "\n\n".join(blocks)


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The ``setdiff-bench`` parser.

    Args:
        argv: the words about to be parsed, or ``None`` for the full parser.  Given, only the verb they
            name is imported and gets its options (the others are listed from their sources), so that
            ``setdiff-bench --help`` and ``setdiff-bench <verb> --help`` load no more than they show.
    """
    parser = OneLineArgumentParser(
        prog="setdiff-bench",
        description="Benchmark and enhance 3D Gaussian Splatting renders far from the recorded trajectory.",
    )
    parser.add_argument("--version", action="version", version=f"setdiff-bench {__version__}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB", required=True)
    if argv is None:
        modules = {module.VERB: module for module in verb_modules()}
        summaries = {verb: module.HELP for verb, module in modules.items()}
    else:
        summaries = verb_summaries()
        chosen = next((word for word in argv if not word.startswith("-")), None)
        modules = (
            {chosen: importlib.import_module(f"setdiff_bench.cli.{chosen}")} if chosen in summaries else {}
        )
    for verb, summary in summaries.items():
        if verb not in modules:  # listed for the top-level help and for "invalid choice"; never parsed
            sub.add_parser(verb, help=summary)
            continue
        module = modules[verb]
        verb_parser = sub.add_parser(
            verb,
            help=summary,
            description=getattr(module, "DESCRIPTION", summary),
            formatter_class=ParagraphHelpFormatter,
        )
        module.add_arguments(verb_parser)
        verb_parser.set_defaults(_run=module.run)
    return parser


def command_parsers(
    parser: argparse.ArgumentParser, args: argparse.Namespace
) -> list[argparse.ArgumentParser]:
    """The parsers ``args`` went through, outermost first: ``setdiff-bench weights list`` → the top parser,
    the ``weights`` parser and the ``weights list`` sub-parser."""
    chain = [parser]
    while True:
        sub = next((a for a in chain[-1]._actions if isinstance(a, argparse._SubParsersAction)), None)
        name = getattr(args, sub.dest, None) if sub is not None else None
        if sub is None or name not in sub.choices:
            return chain
        chain.append(sub.choices[name])


def chosen_parser(parser: argparse.ArgumentParser, args: argparse.Namespace) -> argparse.ArgumentParser:
    """The innermost parser ``args`` went through: ``setdiff-bench weights list`` → the ``weights list``
    sub-parser, so that a usage error names the help that lists the right options."""
    return command_parsers(parser, args)[-1]


def parameter_options(parser: argparse.ArgumentParser, args: argparse.Namespace) -> dict[str, str]:
    """How the command line ``args`` came from spells each library parameter: ``{dest: option}`` for every
    argument of the parsers it went through (``{"checkpoint": "--checkpoint", "source": "--from"}``; ``""`` for
    a positional argument, which an error then names by its value alone), so that an error raised with
    ``parameter="source"`` names ``--from``
    (:meth:`~setdiff_bench.errors.SetDiffBenchError.one_line`).

    A sub-command's argument wins over its verb's of the same ``dest``, a long option over a short one, and a
    shown option over a hidden one.
    """
    options: dict[str, str] = {}
    for command in reversed(command_parsers(parser, args)):
        actions = sorted(command._actions, key=lambda action: action.help == argparse.SUPPRESS)  # shown first
        for action in actions:
            if action.dest in (argparse.SUPPRESS, "help") or isinstance(action, argparse._SubParsersAction):
                continue
            long = [option for option in action.option_strings if option.startswith("--")]
            options.setdefault(action.dest, (long or action.option_strings or [""])[0])
    return options


@contextlib.contextmanager
def one_line_warnings(verb: str) -> Iterator[None]:
    """Show the toolkit's own warnings (classes defined in ``setdiff_bench``) as one line
    ``setdiff-bench <verb>: warning: <message>`` on stderr, as errors are shown; others as Python shows them."""
    with warnings.catch_warnings():
        python_show = warnings.showwarning

        def show(message: Warning | str, category: type[Warning], *args: object, **kwargs: object) -> None:
            if category.__module__.startswith("setdiff_bench"):
                print(f"setdiff-bench {verb}: warning: {' '.join(str(message).split())}", file=sys.stderr)
            else:
                python_show(message, category, *args, **kwargs)  # type: ignore[arg-type]

        warnings.showwarning = show
        yield


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv`` and run the verb; returns the process exit code."""
    words = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(words)
    args, extras = parser.parse_known_args(words)
    if extras:  # reported by the (sub-)command they were given to, with its --help
        chosen_parser(parser, args).error(f"unrecognized arguments: {' '.join(extras)}")
    #: the command as typed, for the records a verb writes (training manifests)
    args.command_line = "setdiff-bench " + shlex.join(words)
    try:
        with verb_threads(), one_line_warnings(args.verb):  # one fixed thread count: same bytes
            return int(args._run(args) or 0)
    except SetDiffBenchError as error:
        if os.environ.get("SETDIFF_DEBUG"):
            raise
        options = parameter_options(parser, args)
        print(f"setdiff-bench {args.verb}: error: {error.one_line(options)}", file=sys.stderr)
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
