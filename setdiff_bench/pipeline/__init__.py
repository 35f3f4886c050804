"""Whole pipelines of CLI stages as separate processes: the embedded demo and the stage runner."""
