"""A template setdiff-bench enhancer plugin: an unsharp mask on each rendered target (see README.md)."""
