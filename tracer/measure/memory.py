"""Memory guard: estimate before allocating; refuse with the estimate when over the budget."""
from __future__ import annotations

import functools
import os

from tracer.errors import GridcostError
from tracer.settings import current, parse_bytes as _parse_bytes

#: default fraction of physical RAM one structure may allocate before the guard refuses (a setting
#: of gridcost, not a paper constant)
MEMORY_BUDGET_FRACTION = 0.5


def physical_ram() -> int:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        return 8 << 30


def memory_budget() -> int:
    """Bytes one structure may allocate: $GRIDCOST_MEMORY_BUDGET (e.g. '2G') or half the RAM."""
    budget = current().memory_budget
    return budget if budget is not None else int(physical_ram() * MEMORY_BUDGET_FRACTION)


def cache_bytes(level: int = 2) -> int:
    """Size of cpu0's level-``level`` data/unified cache from sysfs ($GRIDCOST_L2 / $GRIDCOST_L3
    override, e.g. '1M'); 32 KiB (L1), 1 MiB (L2) or 32 MiB (L3) when unknown."""
    sizes = current().cache_sizes
    if 1 <= level <= len(sizes) and sizes[level - 1] is not None:
        return sizes[level - 1]
    return _sysfs_cache_bytes(level)


@functools.lru_cache(maxsize=None)
def _sysfs_cache_bytes(level: int) -> int:
    """sysfs lookup, once per process (every grid build asks)."""
    base = "/sys/devices/system/cpu/cpu0/cache"
    try:
        for entry in sorted(os.listdir(base)):
            with open(f"{base}/{entry}/level") as f:
                lev = int(f.read())
            with open(f"{base}/{entry}/type") as f:
                kind = f.read().strip()
            if lev == level and kind in ("Data", "Unified"):
                with open(f"{base}/{entry}/size") as f:
                    return _parse_bytes(f.read())
    except (OSError, ValueError):
        pass
    return {1: 32 << 10, 2: 1 << 20}.get(level, 32 << 20)


def fmt_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if abs(n) < 1024 or unit == "TiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.1f} TiB"


def check_budget(what: str, estimate: int, budget: int | None = None) -> None:
    budget = memory_budget() if budget is None else budget
    if estimate > budget:
        raise GridcostError(
            f"{what} would need about {fmt_bytes(estimate)}, over the memory budget of {fmt_bytes(budget)} "
            f"(set GRIDCOST_MEMORY_BUDGET to raise it, or use fewer cells)")


def working_set(index, refs, triangles) -> dict:
    """The bytes a structure's rays read, by kind: ``index`` (cell array or tree nodes), ``refs``
    (reference lists / primitive ids) and ``triangles`` (vertex data), and their total — the
    working set the memory-aware cost model (:mod:`costmodel.memory`) prices against the caches."""
    ws = {"index": int(index), "refs": int(refs), "triangles": int(triangles)}
    ws["total"] = sum(ws.values())
    return ws
