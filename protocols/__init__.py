"""Evaluation protocols (installed as ``setdiff_bench.protocols``): TOML definitions, split lists, reported numbers."""
