"""Dataset loaders (installed as ``setdiff_bench.loaders``): official on-disk layouts → :class:`Scene` objects."""
