"""Performance scripts: each compares against a peer in the same run and writes benchmarks/results/<name>.json."""
