"""Where a structure's traversal arrays live: aligned to a cache line, and, from one huge page up, in
memory advised for transparent huge pages.

Embree's allocator maps its BVH memory itself and advises the kernel to back it with 2 MiB pages
(``common/sys/alloc.cpp``: ``os_malloc`` -> ``os_advise`` -> ``madvise(ptr, bytes, MADV_HUGEPAGE)``).
On a host whose transparent huge pages are set to ``madvise`` (this VM's setting), memory that is
not advised stays on 4 KiB pages, so a ray that misses cache in a 10-80 MiB structure also misses
the TLB and walks the page tables. Placing our arrays as Embree places its own removes that
difference from the comparison. It is small on this AMD host (paired huge / 4 KiB time, one thread,
t and id unchanged, on dragon-202k, dragon-871k and homer-x16): wide BVH 0.96-0.99 on random rays
and 0.99-1.00 on camera rays; grid 0.96-1.00; kd-tree, BVH4, packets and the nested grid 0.98-1.01.

Where the kernel does not grant huge pages (THP ``never``, other systems, no ``madvise``), the
array is an ordinary aligned copy: same values, same layout, 4 KiB pages as before.
:func:`thp_mode` names the host's setting for the measurement records.
"""
from __future__ import annotations

import ctypes
import mmap
import weakref

import numpy as np

#: bytes of one transparent huge page on x86-64 and most arm64 kernels
HUGE_PAGE = 2 << 20
#: byte alignment of every traversal array: a 256-byte wide-BVH node spans 4 cache lines, not 5
ALIGN = 64
#: tracemalloc domain numpy reports its buffers under (numpy/_core/include/numpy/ndarraytypes.h)
NUMPY_TRACE_DOMAIN = 389047
#: the kernel's transparent-huge-page policy (the bracketed word is the one in force)
THP_POLICY = "/sys/kernel/mm/transparent_hugepage/enabled"


def _advised_region(nbytes: int) -> np.ndarray | None:
    """A uint8 view of a fresh anonymous mapping of ``nbytes`` + one huge page (room to start on a
    huge-page boundary), advised for huge pages; None where that cannot be had."""
    if not hasattr(mmap, "MADV_HUGEPAGE"):
        return None
    size = -(-(nbytes + HUGE_PAGE) // HUGE_PAGE) * HUGE_PAGE
    try:
        region = mmap.mmap(-1, size, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
    except OSError:
        return None
    try:
        region.madvise(mmap.MADV_HUGEPAGE)
    except OSError:  # THP compiled out: the mapping still serves, on 4 KiB pages
        pass
    buf = np.frombuffer(region, np.uint8)  # the array keeps the mapping alive (its base)
    _traced(buf, nbytes)
    return buf


def _traced(buf: np.ndarray, nbytes: int) -> None:
    """Report the mapping's ``nbytes`` to tracemalloc under numpy's domain, as numpy reports its own
    buffers, so memory accounting (tracemalloc peaks, and the build footprint model fitted on
    them, :mod:`tracer.measure.footprint`) sees it; withdrawn when the mapping is released."""
    api = getattr(ctypes, "pythonapi", None)
    if api is None:
        return
    addr = ctypes.c_size_t(buf.ctypes.data)
    if api.PyTraceMalloc_Track(ctypes.c_uint(NUMPY_TRACE_DOMAIN), addr, ctypes.c_size_t(nbytes)) == 0:
        weakref.finalize(buf, api.PyTraceMalloc_Untrack, ctypes.c_uint(NUMPY_TRACE_DOMAIN), addr)


def traversal_empty(shape, dtype) -> np.ndarray:
    """An uninitialised C-contiguous, writable array that starts on an ALIGN-byte boundary; from
    HUGE_PAGE bytes up, on a huge-page boundary of memory advised for huge pages. Builds that fill
    their arrays in place allocate them here, so no copy raises their peak."""
    dtype = np.dtype(dtype)
    nbytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    buf = _advised_region(nbytes) if nbytes >= HUGE_PAGE else None
    step = HUGE_PAGE
    if buf is None:
        buf, step = np.empty(nbytes + ALIGN, np.uint8), ALIGN
    off = (-buf.ctypes.data) % step
    return buf[off:off + nbytes].view(dtype).reshape(shape)


def traversal_array(a: np.ndarray) -> np.ndarray:
    """A copy of ``a`` in :func:`traversal_empty` memory (same values, C order)."""
    out = traversal_empty(np.shape(a), np.asarray(a).dtype)
    out[...] = a
    return out


def traversal_rows(a: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``a[rows]`` gathered straight into :func:`traversal_empty` memory (no intermediate copy;
    mode "clip" because the default "raise" stages the result in a temporary; rows are in range)."""
    out = traversal_empty((len(rows), *a.shape[1:]), a.dtype)
    return np.take(a, rows, axis=0, out=out, mode="clip")


def traversal_concat(parts, dtype) -> np.ndarray:
    """``np.concatenate(parts).astype(dtype)`` written straight into :func:`traversal_empty` memory
    (one pass, no intermediate; the cast is the unchecked one ``astype`` makes)."""
    rows = sum(len(p) for p in parts)
    out = traversal_empty((rows, *np.shape(parts[0])[1:]), dtype)
    return np.concatenate(parts, out=out, casting="unsafe")


def thp_mode() -> str:
    """This host's transparent-huge-page policy (``always``, ``madvise``, ``never``), or
    ``unavailable`` where the kernel does not say."""
    try:
        with open(THP_POLICY) as f:
            words = f.read().split()
    except OSError:
        return "unavailable"
    return next((w[1:-1] for w in words if w.startswith("[")), "unavailable")
