"""The ``setdiff-bench`` command line: one module per verb, discovered at start-up.

A verb module defines ``VERB`` (its name), ``HELP`` (one line), ``add_arguments(parser)`` and
``run(args) -> int``.  Verb modules import nothing heavy at module level, so ``--help`` is fast.
"""
