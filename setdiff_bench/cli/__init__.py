"""The ``setdiff-bench`` command line: one module per verb, discovered at start-up.

A verb module defines ``VERB`` (its name), ``HELP`` (one line), ``add_arguments(parser)`` and
``run(args) -> int``.  Verb modules import nothing heavy at module level, so ``--help`` is fast.

Options that several verbs share are declared here, once, so that they are spelled, defaulted and
explained alike: :func:`add_device_argument` (``--device``, default ``auto``),
:func:`add_progress_argument` (``--no-progress``) and :func:`add_option_argument` (``-o KEY=VALUE``).
Older spellings stay accepted, hidden from ``--help``, for one release.  :func:`settings_from` turns
parsed arguments into a verb's settings dataclass (fields read by their own names, the rest derived);
:func:`parse_option` reads one ``KEY=VALUE`` and :func:`method_options` gathers an enhancer's options from ``-o``
and the flags that stand for some of them.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any, TypeVar

from setdiff_bench.errors import UsageError

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
    of strings (``args.option``) for :func:`parse_option`; ``help`` explains it."""
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


def method_options(args: argparse.Namespace, *flags: str, path_flags: tuple[str, ...] = ()) -> dict[str, Any]:
    """An enhancer's options: the ``-o KEY=VALUE`` list (``args.option``) plus the flags that stand for one of
    them (``flags``: option names, read from ``args`` by the same name; None: not given).  A ``path_flags``
    value naming an existing path is made absolute, so that a resumed run matches its record whatever the
    working folder; anything else is kept as given (a shipped model's name such as ``tiny_setdiff``).

    Raises:
        UsageError: an option given both as a flag and with ``-o``.
    """
    options = dict(parse_option(text) for text in args.option)
    for key in (*flags, *path_flags):
        value = getattr(args, key)
        if value is None:
            continue
        if key in options:
            raise UsageError(f"{key} given twice (flag and -o)", "--option")
        if key in path_flags:
            path = Path(value).expanduser()
            value = str(path.resolve()) if path.exists() else value
        options[key] = value
    return options


def parse_option(text: str, flag: str = "-o/--option") -> tuple[str, Any]:
    """``KEY=VALUE`` → ``(key, value)``; the value is parsed as JSON when it is valid JSON, else kept as text.

    ``level=1`` → 1, ``sweeps=false`` → False, ``channels=["CAM_FRONT"]`` → list, ``version=v1.0-mini`` → str.
    The one parser of every ``KEY=VALUE`` flag (loader options: :func:`setdiff_bench.cli.list.loader_options`; ``run -o``'s method
    options); ``flag`` is the argument a malformed ``text`` is reported against.
    """
    key, sep, raw = text.partition("=")
    if not sep or not key.strip():
        raise UsageError(f"option {text!r} must look like KEY=VALUE", flag)
    try:
        value = json.loads(raw)
    except json.JSONDecodeError:
        value = raw
    return key.strip(), value
