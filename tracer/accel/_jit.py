"""The one Numba decorator configuration every kernel uses.

``cache=True`` so compiled kernels survive between runs, ``fastmath=False`` so float semantics are
IEEE (the oracle agreement depends on it), ``error_model='numpy'`` so 1/0 gives inf (slab tests)
instead of raising.

The cache lives in a folder named by the digest of every source file of ``tracer/``
(:func:`tracer.measure.provenance.numba_cache_dir`): Numba invalidates a cached function only when its own
file changes, while our kernels inline ``geometry.ray_triangle``, ``dda_setup`` and
:func:`store_ray` from other files, so an edit to ``geometry.py`` could otherwise leave the grid
running old machine code. Every kernel is decorated through :func:`jit` / :func:`pjit` (or
:func:`ray_jit` for a per-ray walk the batched kernels call), which point Numba at that folder at
decoration time (when Numba picks a function's cache locator).
"""
import os
import sys

import numpy as np
from numba import config, njit
from numba.core import caching

from tracer.measure.provenance import numba_cache_dir

CACHE_DIR = str(numba_cache_dir())


def _dropped(cache_file, exc) -> None:
    """An unreadable cache entry (a kill or a full disk mid-write): its index goes, so Numba compiles
    the function again and writes a fresh entry; one line says so."""
    path = cache_file._index_path
    try:
        os.unlink(path)
    except OSError:
        pass
    print(f"gridcost: dropped an unreadable compiled-kernel cache entry {path} ({type(exc).__name__}); "
          "recompiling it", file=sys.stderr)


def _healing(load_index, load):
    """Numba's cache reads, with an unreadable file treated as a miss instead of a crash."""
    def _load_index(self):
        try:
            return load_index(self)
        except Exception as exc:  # truncated or foreign pickle: UnpicklingError, EOFError, ValueError...
            _dropped(self, exc)
            return {}

    def _load(self, key):
        try:
            return load(self, key)
        except Exception as exc:
            _dropped(self, exc)
            return None
    return _load_index, _load


if not getattr(caching.IndexDataCacheFile, "_gridcost_heals", False):  # once per process, on first import
    caching.IndexDataCacheFile._load_index, caching.IndexDataCacheFile.load = _healing(
        caching.IndexDataCacheFile._load_index, caching.IndexDataCacheFile.load)
    caching.IndexDataCacheFile._gridcost_heals = True
_OPTIONS = dict(cache=True, fastmath=False, error_model="numpy", nogil=True)


def _decorate(options, args, kwargs):
    config.CACHE_DIR = CACHE_DIR  # read by Numba's cache locator when the dispatcher is created
    opts = {**options, **kwargs}
    if len(args) == 1 and callable(args[0]):
        return njit(**opts)(args[0])
    return njit(*args, **opts)


def jit(*args, **kwargs):
    """``@jit`` or ``@jit(inline="always")``: njit with the project's options and cache folder."""
    return _decorate(_OPTIONS, args, kwargs)


def ray_jit(fn):
    """A per-ray (or per-packet) kernel that batched ``prange`` kernels call: compiled once per argument
    types and inlined by LLVM (``forceinline``: the alwaysinline attribute) into each caller.

    Why not ``inline="always"``: Numba then copies the function's IR into every call site and types
    it there again, and once more when the prange body is outlined into its gufunc, so the grid's
    batched kernel took 10 s to compile per variant (about 4 s this way, and the same run time).
    ``_nrt=False``: no reference counting of the array arguments at each call (with it, the inlined
    call paid an incref/decref of every array per ray, 5-15 % of the grid's time); such a kernel
    allocates nothing, and Numba refuses to compile one that does."""
    return _decorate(_OPTIONS, (fn,), dict(forceinline=True, _nrt=False))


def pjit(*args, **kwargs):
    """:func:`jit` with ``parallel=True`` (kernels that ``prange`` over ray blocks)."""
    return _decorate({**_OPTIONS, "parallel": True}, args, kwargs)


#: rays per scheduling block. Batched kernels run ``for th in prange(T)`` (T = get_num_threads())
#: and thread ``th`` takes blocks th, th + T, th + 2T, ... (``range(th, nblocks(m), T)``): Numba's
#: prange hands each thread one contiguous slice, and a camera image's halves cost different
#: amounts (1.3x on bunny-69k), so contiguous halves scaled 1.67x on 2 threads; interleaved blocks
#: keep the rays of a block coherent and balance the load.
BLOCK = 256


@jit(inline="always")
def nblocks(m):
    """Number of BLOCK-ray blocks covering m rays."""
    return (m + BLOCK - 1) // BLOCK


@jit(inline="always")
def pop_within(st, sp, lim):
    """The pop of every stack traversal (BVH, BVH4, wide BVH, kd-tree): the index of the topmost of the
    ``sp`` pending entries whose entry distance ``st`` is not beyond ``lim`` (the closest hit so far,
    plus the tolerance where the kernel widens it), or -1 when none is. The entries above it start
    after the closest hit and are dropped, not a stop: the stacks are not ordered by entry distance.
    The new stack height is the index. ``not lim < st`` keeps an entry whose distance is NaN."""
    while sp > 0:
        sp -= 1
        if not lim < st[np.uintp(sp)]:
            return sp
    return -1


@jit(inline="always")
def store_ray(out_t, out_id, counters, i, t, tid, setups, steps, tests, nodes, skips, occupied=0, jumps=0):
    """Write ray i's result and, when ``counters`` is an array (not None), its counters in the
    column order of :data:`tracer.accel.COUNTER_NAMES`."""
    out_t[i] = t
    out_id[i] = tid
    if counters is not None:
        counters[i, 0] = setups
        counters[i, 1] = steps
        counters[i, 2] = tests
        counters[i, 3] = nodes
        counters[i, 4] = skips
        counters[i, 5] = occupied
        counters[i, 6] = jumps
