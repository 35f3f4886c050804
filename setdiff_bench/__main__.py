"""``python -m setdiff_bench`` = the ``setdiff-bench`` command."""

import sys

from setdiff_bench.cli.main import main

sys.exit(main())
