"""setdiff-bench: benchmark and enhancers for 3D Gaussian Splatting novel-view synthesis.

The data path (see ``docs/architecture.md``): loaders → protocols → fit → render → packets →
enhancers → metrics → leaderboards.  Importing the package is cheap: heavy parts load lazily.
"""

from setdiff_bench.errors import SetDiffBenchError

__version__ = "0.1.0"
__all__ = ["SetDiffBenchError", "__version__"]
