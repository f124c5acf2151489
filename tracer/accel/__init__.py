"""Acceleration structures, the float64 oracle and the kernel helpers they share.

Every module here that holds a Numba kernel is hashed into the Numba cache folder and the
measurement key (:func:`tracer.measure.provenance.kernel_digest`); scene data and docs are not.

The interface (:mod:`tracer.accel.base`) is re-exported here: ``from tracer.accel import build``.
"""
from tracer.accel.base import (COUNTER_NAMES, STRUCTURES, Accel, Counters, Hits, TreeTraceMixin, as_rays,  # noqa: F401
                               plugin_structures, structure_class, structures,
                               build, tmax_array)
