"""The methods this package trains and runs, declared once (a leaf: the config's ``method`` field and the CLI's
``--method`` choices read it without importing the networks)."""

from __future__ import annotations

from typing import Literal

#: ``setdiff``: the set-based enhancer; ``difix``: DiFix, one target and its best reference.
Method = Literal["setdiff", "difix"]
