"""Protocol files: the packaged ones (:func:`list_protocols`, :func:`protocol_path`), and reading and validating
one (:func:`load_protocol`, :func:`parse_protocol`) into the model of :mod:`.model`.  Every problem is a
:class:`~setdiff_bench.errors.ProtocolError` naming the file and key."""

from __future__ import annotations

import os
import tomllib
from collections.abc import Mapping
from fractions import Fraction
from importlib import resources
from pathlib import Path
from typing import Any

from setdiff_bench.errors import ProtocolError
from setdiff_bench.protocols import profiles  # its PROFILES read per call

from .model import (
    POOLED,
    SPLITS,
    Block,
    GroupSpec,
    ImageSpec,
    Layout,
    PacketSpec,
    Protocol,
    ReferenceSpec,
)
from .rules import RULES
from .scene_split import SceneSplit, read_split_list
from .schema import Table

FORMAT = "setdiff-protocol/1"
PROTOCOL_NAMES = ("euvs", "paralane", "nuscenes", "dl3dv", "synthetic", "colmap", "nerfstudio")


def protocol_dir() -> Path:
    """The folder holding the packaged protocol files."""
    return Path(str(resources.files(__package__)))


def list_protocols() -> list[str]:
    """Names of the packaged protocols."""
    return sorted(p.stem for p in protocol_dir().glob("*.toml"))


def protocol_path(name_or_path: str | os.PathLike[str]) -> Path:
    """A packaged protocol name (``euvs``) or a path to a TOML file → the file."""
    text = os.fspath(name_or_path)
    candidate = Path(text)
    if candidate.suffix == ".toml" or os.sep in text or "/" in text:
        if not candidate.is_file():
            raise ProtocolError("protocol file not found", candidate, parameter="protocol")
        return candidate
    packaged = protocol_dir() / f"{text}.toml"
    if not packaged.is_file():
        raise ProtocolError(
            f"unknown protocol {text!r}; packaged: {', '.join(list_protocols())} "
            "(or pass a path to a .toml file)",
            parameter="protocol",
        )
    return packaged


def load_protocol(name_or_path: str | os.PathLike[str]) -> Protocol:
    """Load and validate a protocol (packaged name or path).

    Raises:
        ProtocolError: the file is missing, not TOML, or a key is missing, unknown or invalid.
    """
    path = protocol_path(name_or_path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ProtocolError(f"invalid TOML: {exc}", path) from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise ProtocolError(f"cannot read protocol file ({exc.__class__.__name__})", path) from exc
    return parse_protocol(data, path)


def parse_protocol(data: Mapping[str, Any], path: Path) -> Protocol:
    """Validate parsed TOML ``data`` (read from ``path``, named in errors) into a :class:`Protocol`."""
    root = Table(data, path)
    root.check_keys(
        (
            "format",
            "name",
            "dataset",
            "description",
            "loader",
            "split",
            "images",
            "references",
            "packets",
            "render",
            "groups",
            "evaluation",
            "leaderboard",
        )
    )
    if root.raw("format") != FORMAT:
        raise root.error("format", f"expected {FORMAT!r}, got {root.raw('format')!r}")
    loader = root.table("loader", {})
    references = _references(root.table("references"))
    packets = _packets(root.table("packets"))
    for split in SPLITS:
        if references.count[split] >= packets.views[split]:
            raise root.error(
                f"references.{split}",
                f"N = {references.count[split]} leaves no target in a packet of "
                f"{packets.views[split]} views (packets.{split}_views)",
            )
    render = root.table("render", {})
    render.check_keys(("cmap_clip",))
    groups = tuple(_group(t) for t in root.tables("groups"))
    names = [g.name for g in groups]
    duplicate = next((n for n in names if names.count(n) > 1), None)
    if duplicate:
        raise root.error("groups", f"group name {duplicate!r} appears twice")
    dataset = root.string("dataset")
    leaderboard = _leaderboard(root.table("leaderboard"), names, dataset) if root.has("leaderboard") else None
    return Protocol(
        name=root.string("name"),
        dataset=dataset,
        description=root.string("description", "-"),
        path=path,
        loader_options=dict(loader.data),
        split=_split(root.table("split")),
        images=_images(root.table("images")),
        references=references,
        packets=packets,
        cmap_clip=render.number("cmap_clip", 0.0, minimum=0.0),
        groups=groups,
        evaluation=_evaluation(root.table("evaluation", {})),
        leaderboard=leaderboard,
    )


# ---------------------------------------------------------------------- sections
def _split(table: Table) -> SceneSplit:
    rule = table.string("rule", choices=("interleaved", "every_nth", "list"))
    if rule == "interleaved":
        table.check_keys(("rule", "test_fraction"))
        value = table.integers("test_fraction", minimum=0)
        if len(value) != 2 or not 0 < value[0] < value[1]:
            raise table.error(
                "test_fraction",
                f"expected [numerator, denominator] with 0 < numerator < denominator, got {value!r}",
            )
        numerator, denominator = value
        return SceneSplit("interleaved", test_fraction=Fraction(numerator, denominator))
    if rule == "every_nth":
        table.check_keys(("rule", "every"))
        return SceneSplit("every_nth", every=table.integer("every", minimum=2))
    table.check_keys(("rule", "file"))
    relative = table.string("file")
    file = (table.path.parent / relative).resolve()
    if not file.is_file():
        raise table.error("file", f"split list {file} not found")
    names = read_split_list(file)
    if not names:
        raise table.error("file", f"split list {file} is empty")
    return SceneSplit("list", test_names=names, list_file=file)


def _images(table: Table) -> ImageSpec:
    table.check_keys(("resolution", "resize", "masks", "downscale"))
    value = table.raw("resolution")
    if value == "native":
        resolution = None
    else:
        size = table.integers("resolution", minimum=1)
        if len(size) != 2:
            raise table.error("resolution", f'expected [height, width] or "native", got {value!r}')
        resolution = (size[0], size[1])
    return ImageSpec(
        resolution=resolution,
        resize=table.string("resize", "crop", choices=("crop", "stretch")),
        masks=table.string("masks", choices=("dataset", "foreground", "none")),  # type: ignore[arg-type]
        downscale=table.integer("downscale", 1, minimum=1),
    )


def _evaluation(table: Table) -> tuple[str, ...]:
    table.check_keys(("profiles",))
    names = table.strings("profiles", ["paper"])
    unknown = [name for name in names if name not in profiles.PROFILES]
    if unknown:
        raise table.error(
            "profiles", f"unknown profile {unknown[0]!r}; known: {', '.join(profiles.PROFILES)}"
        )
    return names


def _leaderboard(table: Table, groups: list[str], dataset: str) -> Layout:
    table.check_keys(("title", "blocks", "metrics", "sequence_metrics", "reported_tables"))
    blocks: tuple[Block, ...] | None = None
    if table.has("blocks"):
        value = table.raw("blocks")
        if not isinstance(value, list) or not value or not all(isinstance(v, Mapping) for v in value):
            raise table.error(
                "blocks",
                f"expected a non-empty list of tables ({{ group = ..., label = ... }}), got {value!r}",
            )
        blocks = tuple(
            _block(Table(v, table.path, f"{table.key('blocks')}[{i}]"), groups) for i, v in enumerate(value)
        )
        keys = [b.key for b in blocks]
        duplicate = next((k for k in keys if keys.count(k) > 1), None)
        if duplicate is not None:
            raise table.error(
                "blocks",
                "the pooled block appears twice"
                if duplicate == POOLED
                else f"group {duplicate!r} appears twice",
            )
    metrics = table.strings("metrics", list(Layout.metrics))
    sequence_metrics = table.strings("sequence_metrics") if table.has("sequence_metrics") else ()
    _check_metrics(table, "metrics", metrics, "image")
    _check_metrics(table, "sequence_metrics", sequence_metrics, "sequence")
    reported = table.strings("reported_tables") if table.has("reported_tables") else ()
    if reported:
        known = _reported_tables(table, dataset)
        unknown = [name for name in reported if name not in known]
        if unknown:
            raise table.error(
                "reported_tables",
                f"no reported table {unknown[0]!r} of dataset {dataset!r} in "
                f"protocols/reported/*.csv; known: {', '.join(sorted(known)) or 'none'}",
            )
    return Layout(
        blocks=blocks,
        metrics=metrics,
        sequence_metrics=sequence_metrics,
        reported_tables=reported,
        title=table.string("title") if table.has("title") else "",
    )


def _block(table: Table, groups: list[str]) -> Block:
    table.check_keys(("group", "pooled", "label"))
    label = table.string("label")
    if table.has("pooled"):
        if table.has("group"):
            raise table.error("pooled", "a block has either group or pooled = true, not both")
        if not table.boolean("pooled"):
            raise table.error("pooled", "expected true (leave the key out otherwise)")
        return Block(POOLED, label)
    if not table.has("group"):
        raise table.error("group", "missing required key (or pooled = true)")
    group = table.string("group")
    if group not in groups:
        raise table.error("group", f"no group {group!r} in this protocol; groups: {', '.join(groups)}")
    return Block(group, label)


def _check_metrics(table: Table, key: str, names: tuple[str, ...], scope: str) -> None:
    # lazy: the metric registry imports torch; protocols stay light
    from setdiff_bench.metrics.registry import METRICS

    for name in names:
        if name not in METRICS or METRICS[name].scope != scope:
            known = ", ".join(n for n, spec in METRICS.items() if spec.scope == scope)
            raise table.error(key, f"unknown {scope} metric {name!r}; known: {known}")


def _reported_tables(table: Table, dataset: str) -> set[str]:
    """``table`` ids of the packaged ``reported/*.csv`` rows of ``dataset``."""
    import csv

    known: set[str] = set()
    for file in sorted((protocol_dir() / "reported").glob("*.csv")):
        try:
            with file.open(encoding="utf-8", newline="") as handle:
                known.update(
                    row.get("table", "") for row in csv.DictReader(handle) if row.get("dataset") == dataset
                )
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            raise table.error(
                "reported_tables", f"cannot read {file.name} ({exc.__class__.__name__})"
            ) from exc
    return known


def _references(table: Table) -> ReferenceSpec:
    table.check_keys(("alpha", "beta", "aggregate", "train", "test"))
    return ReferenceSpec(
        alpha=table.number("alpha", minimum=0.0),
        beta=table.number("beta", minimum=0.0),
        aggregate=table.string("aggregate", "mean", choices=("mean", "max")),  # type: ignore[arg-type]
        count={s: table.integer(s, minimum=1) for s in SPLITS},
    )


def _packets(table: Table) -> PacketSpec:
    table.check_keys(("train_views", "test_views", "train_min_views", "train_max_views"))
    views = {s: table.integer(f"{s}_views", minimum=2) for s in SPLITS}
    low, high = table.integer("train_min_views", minimum=2), table.integer("train_max_views", minimum=2)
    if not low <= high <= views["train"]:
        raise table.error(
            "train_max_views",
            f"expected train_min_views <= train_max_views <= train_views, got "
            f"{low}, {high}, {views['train']}",
        )
    return PacketSpec(views=views, train_views=(low, high))


def _group(table: Table) -> GroupSpec:
    rule_name = table.string("rule", choices=tuple(RULES))
    reserved = {"name", "rule", "fit_key", "scenes"}
    params = Table({k: v for k, v in table.data.items() if k not in reserved}, table.path, table.prefix)
    scenes: dict[str, tuple[Any, ...]] = {}
    if table.has("scenes"):
        for key, value in table.table("scenes").data.items():
            scenes[key] = tuple(value) if isinstance(value, list) else (value,)
    name = table.string("name")
    fit_key = table.string("fit_key")
    for label, value in (("name", name), ("fit_key", fit_key)):
        if any(c in value for c in "/\\") or value.startswith(".") or value.startswith("_") or "__" in value:
            raise table.error(
                label, f"must not contain '/', '\\' or '__' nor start with '.' or '_', got {value!r}"
            )
    return GroupSpec(
        name=name, rule=rule_name, params=RULES[rule_name].validate(params), fit_key=fit_key, scenes=scenes
    )
