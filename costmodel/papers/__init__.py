"""The papers' own numbers, as data: one module per paper, each value with its unit, where it stands
and the verbatim quote that holds it (:mod:`costmodel.papers.cite`).

============================  ===================================================================
module                        paper
============================  ===================================================================
:mod:`.ize2007`               Ize, Shirley & Parker 2007, grid creation strategies (Tables 2-4)
:mod:`.hapala2011`            Hapala, Karlik & Havran 2011, when to use uniform grids (Table 1)
:mod:`.wald2006`              Wald et al. 2006, coherent grid traversal (Tables 1, 3, 4)
:mod:`.fournier1993`          Fournier & Poulin 1993, hierarchy of 1D sorted lists (Table 1)
============================  ===================================================================
"""
from __future__ import annotations

import importlib

from costmodel.papers.cite import Cited, CitedTable, Derived

MODULES = ("ize2007", "hapala2011", "wald2006", "fournier1993")


def module(name: str):
    return importlib.import_module(f"costmodel.papers.{name}")


def walk(obj):
    """Every :class:`Cited` and :class:`CitedTable` inside ``obj`` (nested dicts, tuples, lists)."""
    if isinstance(obj, (Cited, CitedTable)):
        yield obj
    elif isinstance(obj, dict):
        for v in obj.values():
            yield from walk(v)
    elif isinstance(obj, (tuple, list)):
        for v in obj:
            yield from walk(v)


def citations(name: str) -> list:
    """Every cited value and table of one paper module (its ``ALL``)."""
    return list(walk(module(name).ALL))


__all__ = ["Cited", "CitedTable", "Derived", "MODULES", "citations", "module", "walk"]
