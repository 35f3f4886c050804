"""The ``setdiff-bench`` command line: one module per verb, discovered at start-up.

A verb module defines ``VERB`` (its name), ``HELP`` (one line), ``add_arguments(parser)`` and
``run(args) -> int``.  Verb modules import nothing heavy at module level, so ``--help`` is fast.

Options that several verbs share are declared here, once, so that they are spelled, defaulted and
explained alike: :func:`add_device_argument` (``--device``, default ``auto``),
:func:`add_progress_argument` (``--no-progress``) and :func:`add_option_argument` (``-o KEY=VALUE``).
Older spellings stay accepted, hidden from ``--help``, for one release.  :func:`settings_from` turns
parsed arguments into a verb's settings dataclass (fields read by their own names, the rest derived).
"""

from __future__ import annotations

import argparse
import dataclasses
from typing import Any, TypeVar

SettingsT = TypeVar("SettingsT")

DEVICES = "auto (cuda when available, else cpu), cpu, cuda or cuda:N"


def add_device_argument(parser: argparse.ArgumentParser, what: str, devices: str = DEVICES) -> None:
    """``--device``, default ``"auto"``: the verb resolves it with :func:`setdiff_bench.runtime.devices.resolve_device`
    (CUDA when available, else the CPU).  ``what`` says what runs on it; ``devices`` lists the accepted names."""
    parser.add_argument("--device", default="auto", help=f"{devices}; {what}; default auto")


def add_progress_argument(parser: argparse.ArgumentParser, *old_names: str) -> None:
    """``--no-progress`` (``args.no_progress``); ``old_names`` (e.g. ``--quiet``) are hidden aliases."""
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    for name in old_names:
        parser.add_argument(name, dest="no_progress", action="store_true", help=argparse.SUPPRESS)


def add_option_argument(
    parser: argparse.ArgumentParser, help: str, names: tuple[str, ...] = ("-o", "--option")
) -> None:
    """A repeatable ``KEY=VALUE`` flag (``-o/--option`` unless ``names`` says otherwise), collected as a list
    of strings (``args.option``) for :func:`setdiff_bench.cli.list.parse_option`; ``help`` explains it."""
    parser.add_argument(*names, action="append", default=[], metavar="KEY=VALUE", help=help)


def settings_from(cls: type[SettingsT], args: argparse.Namespace, **derived: Any) -> SettingsT:
    """``cls`` (a settings dataclass) with every field that ``derived`` does not give read from ``args`` by its own
    name (the verb declares its flags with the fields' names as destinations).

    Raises:
        TypeError: a field is neither derived nor an argument (a verb out of step with its settings).
    """
    values = dict(derived)
    for field in dataclasses.fields(cls):  # type: ignore[arg-type]
        if field.name not in values:
            if not hasattr(args, field.name):
                raise TypeError(f"{cls.__name__}.{field.name}: neither derived nor a parsed argument")
            values[field.name] = getattr(args, field.name)
    return cls(**values)
