"""The procedural benchmarks' worlds, captures and fits: ``world/`` (the driving streets), ``sparse/`` (the sparse-view
plazas), and the modules that write them in each dataset's official layout."""
