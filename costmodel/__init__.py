"""gridcost cost models: ``derive`` (sympy derivations of the paper equations), ``fit`` and ``select``.

Submodules are imported explicitly (``from costmodel import derive``); this package imports nothing heavy.
"""
