"""The one Numba decorator configuration every kernel uses.

``cache=True`` so compiled kernels survive between runs, ``fastmath=False`` so float semantics are
IEEE (the oracle agreement depends on it), ``error_model='numpy'`` so 1/0 gives inf (slab tests)
instead of raising.
"""
from functools import partial

from numba import njit

jit = partial(njit, cache=True, fastmath=False, error_model="numpy", nogil=True)
pjit = partial(njit, cache=True, fastmath=False, error_model="numpy", nogil=True, parallel=True)
