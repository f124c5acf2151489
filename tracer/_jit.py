"""The one Numba decorator configuration every kernel uses.

``cache=True`` so compiled kernels survive between runs, ``fastmath=False`` so float semantics are
IEEE (the oracle agreement depends on it), ``error_model='numpy'`` so 1/0 gives inf (slab tests)
instead of raising.
"""
from functools import partial

from numba import njit

jit = partial(njit, cache=True, fastmath=False, error_model="numpy", nogil=True)
pjit = partial(njit, cache=True, fastmath=False, error_model="numpy", nogil=True, parallel=True)

#: rays per scheduling block. Batched kernels run ``for th in prange(T)`` (T = get_num_threads())
#: and thread ``th`` takes blocks th, th + T, th + 2T, ... (``range(th, nblocks(m), T)``): Numba's
#: prange hands each thread one contiguous slice, and a camera image's halves cost different
#: amounts (1.3x on bunny-69k), so contiguous halves scaled 1.67x on 2 threads; interleaved blocks
#: keep the rays of a block coherent and balance the load.
BLOCK = 256


@njit(cache=True, inline="always")
def nblocks(m):
    """Number of BLOCK-ray blocks covering m rays."""
    return (m + BLOCK - 1) // BLOCK


@njit(cache=True, inline="always")
def store_ray(out_t, out_id, counters, i, t, tid, setups, steps, tests, nodes, skips):
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
