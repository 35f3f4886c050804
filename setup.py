"""Package discovery that pyproject.toml's ``[tool.setuptools.packages.find]`` cannot express alone.

Every package under ``setdiff_bench/`` is found, so a new subpackage needs no entry anywhere.  Two more
live at the repository root, where users of the protocol and loader catalogues look for them, and are
installed inside the package (``pyproject.toml``'s ``package-dir`` maps them): ``loaders/`` as
``setdiff_bench.loaders`` and ``protocols/`` as ``setdiff_bench.protocols``.  A find directive names a
package by its folder, so it would install them as top-level ``loaders`` and ``protocols``; setuptools
allows either a find directive or a list, not both, hence this file.
"""

from setuptools import find_packages, setup

ROOT_PACKAGES = ["setdiff_bench.loaders", "setdiff_bench.protocols"]

setup(packages=find_packages(include=["setdiff_bench", "setdiff_bench.*"]) + ROOT_PACKAGES)
