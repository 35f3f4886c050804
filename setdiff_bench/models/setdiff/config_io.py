"""SetDiff / DiFix config files: TOML in, TOML out.

A config file is TOML with a ``[model]`` table (``preset`` plus overrides, ``[model.unet]`` /
``[model.vae]`` override single architecture keys) and a ``[train]`` table.  The packaged examples
live in ``setdiff_bench/models/setdiff/configs/`` and can be named without a path
(``tiny_setdiff``, ``sd_turbo_setdiff``, ...).  TOML has no null: a key left out means "default".
"""

from __future__ import annotations

import json
import tomllib
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any

from setdiff_bench.errors import UsageError
from setdiff_bench.io.atomic import write_text_atomic
from setdiff_bench.models.setdiff.config import Config, config_from_dict


def packaged_configs() -> dict[str, Path]:
    """The example configs shipped with the package, by name (file stem)."""
    folder = resources.files("setdiff_bench.models.setdiff") / "configs"
    return {Path(str(p)).stem: Path(str(p)) for p in folder.iterdir() if str(p).endswith(".toml")}


def load_config(source: str | Path) -> Config:
    """Read a config from a TOML file, or a packaged config by name (``tiny_setdiff``, ...)."""
    path = Path(source)
    if not path.exists():
        packaged = packaged_configs()
        if str(source) in packaged:
            path = packaged[str(source)]
        else:
            raise UsageError(
                f"config file not found (packaged configs: {', '.join(sorted(packaged))})",
                source,
                parameter="config",
            )
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as error:
        raise UsageError(f"cannot read config TOML: {error}", path) from error
    try:
        return config_from_dict(data, source=str(path))
    except UsageError as error:
        raise UsageError(error.one_line(), path) from error


def config_toml_data(source: str | Path) -> dict[str, dict[str, Any]]:
    """The raw ``{"model": {...}, "train": {...}}`` tables of a TOML config file or packaged name."""
    load_config(source)  # validates, and resolves packaged names
    path = Path(source) if Path(source).exists() else packaged_configs()[str(source)]
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    return {table: dict(data.get(table, {})) for table in ("model", "train")}


def write_config_toml(path: str | Path, data: Mapping[str, Mapping[str, Any]], comment: str = "") -> Path:
    """Write ``{"model": {...}, "train": {...}}`` as a TOML config (flat tables of scalars and lists).

    The result is validated by reading it back with :func:`load_config`.
    """
    lines = [f"# {line}" for line in comment.splitlines()] if comment else []
    for table in ("model", "train"):
        lines.append(f"[{table}]")
        for key, value in data.get(table, {}).items():
            if value is not None:
                lines.append(f"{key} = {_toml_value(value, f'[{table}] {key}')}")
        lines.append("")
    path = Path(path)
    write_text_atomic(path, "\n".join(lines))
    load_config(path)
    return path


def _toml_value(value: Any, where: str) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v, where) for v in value) + "]"
    raise UsageError(f"cannot write {type(value).__name__} values to a TOML config", where)
