"""Published results name no path of the machine that made them (issue 38).

Every file under ``results/`` is read: text files as text, Parquet files through their string columns and
schema metadata.  A command in a published file is written relative to the repository (``runs/demo/...``)
or with a placeholder (``<dir>``), never ``/work/...``, ``/home/...``, ``C:\\...``.
"""

from __future__ import annotations

import re
from pathlib import Path

import pyarrow.parquet as pq

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "results"

#: An absolute path: a POSIX root folder of a machine's home, scratch or data, or a Windows drive, at the
#: start of a token (so ``runs/demo/work/runs`` is relative and passes).
ABSOLUTE = re.compile(
    r"(?:^|[\s`'\"(=:,\[])"
    r"(?:/(?:work|home|tmp|root|Users|mnt|scratch|data|opt|var|private)/"
    r"|[A-Za-z]:\\)"
)
TEXT_SUFFIXES = {".md", ".tex", ".json", ".jsonl", ".csv", ".txt", ".toml", ".yaml", ".yml", ".html"}


def absolute_paths(text: str) -> list[str]:
    """The lines of ``text`` that hold an absolute machine path."""
    return [line.strip() for line in text.splitlines() if ABSOLUTE.search(line)]


def parquet_strings(path: Path) -> str:
    """Every string cell and the key-value metadata of a Parquet file, one per line."""
    table = pq.read_table(path)
    parts: list[str] = []
    metadata = table.schema.metadata or {}
    parts.extend(value.decode("utf-8", "replace") for value in metadata.values())
    for column in table.columns:
        if str(column.type) in {"string", "large_string"}:
            parts.extend(str(value) for value in column.to_pylist() if value is not None)
    return "\n".join(parts)


def published_files() -> list[Path]:
    return sorted(path for path in RESULTS.rglob("*") if path.is_file())


def test_the_pattern_tells_absolute_from_relative() -> None:
    assert absolute_paths("`setdiff-bench run --out /work/exp/ss --packets runs/demo`")
    assert absolute_paths("--runs /home/me/runs")
    assert absolute_paths(r"saved to C:\Users\me\runs")
    assert absolute_paths('"out": "/tmp/x"')
    assert not absolute_paths("--out runs/demo_ae31/work/runs --packets runs/demo/work/packets")
    assert not absolute_paths("intervals (bootstrap by scene, 95 %); see results/synthetic/README.md")


def test_results_hold_no_absolute_machine_path() -> None:
    problems: dict[str, list[str]] = {}
    for path in published_files():
        relative = path.relative_to(RESULTS).as_posix()
        if path.suffix in TEXT_SUFFIXES:
            text = path.read_text(encoding="utf-8", errors="replace")
        elif path.suffix == ".parquet":
            text = parquet_strings(path)
        else:
            continue
        found = absolute_paths(text)
        if found:
            problems[relative] = found[:3]
    assert not problems, problems


def test_every_published_folder_has_a_readme_naming_command_and_revision() -> None:
    folders = sorted(path for path in RESULTS.iterdir() if path.is_dir())
    assert folders
    for folder in folders:
        readme = folder / "README.md"
        assert readme.is_file(), f"{folder.name} has no README.md"
        text = readme.read_text(encoding="utf-8")
        assert "setdiff-bench " in text, f"{folder.name}/README.md names no command"
        assert re.search(r"\b[0-9a-f]{7,40}\b", text), f"{folder.name}/README.md names no revision"


def test_results_readmes_link_only_files_in_the_repository() -> None:
    for readme in sorted(RESULTS.rglob("README.md")):
        text = readme.read_text(encoding="utf-8")
        targets = [t.split("#")[0] for t in re.findall(r"\]\(([^)\s]+)\)", text) if "://" not in t]
        missing = [t for t in targets if t and not (readme.parent / t).exists()]
        assert not missing, f"{readme.relative_to(ROOT)} links to missing files: {missing}"
