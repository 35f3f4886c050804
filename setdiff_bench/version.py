"""The toolkit's version, on the lowest floor: the package face (``setdiff_bench.__version__``), the CLI's
``--version`` and the service's health reply read it from here, so none of them imports the package face for it.
Kept equal to ``pyproject.toml``'s ``[project] version`` (``tests/core/test_version.py``)."""

__version__ = "0.1.0"
