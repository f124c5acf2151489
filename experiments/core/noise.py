"""How noisy this host's clock readings are while a target runs: the meter every meta.json records.

A penalty of 3 % means something on a host whose back-to-back timings of the same work agree to
1 %, and nothing on one where they scatter by 15 % (a cloud VM with busy neighbours: seen here, an
AMD EPYC VM whose 35 ms grid traces read 35-61 ms in turn, against 5 % on an Intel VM). The meter
times two fixed kernels, ``samples`` back-to-back samples each, on one thread with the one-thread
clock of :func:`tracer.measure.timing.default_clock`:

* **compute** — :func:`tracer.measure.timing._probe_kernel` (arithmetic over 512 KiB, the thread-clock check's kernel);
* **memory** — :func:`tracer.measure.machine._chase`, dependent loads once round an 8 MiB random cycle (past the L2
  of the hosts seen; a neighbour's cache and memory traffic shows here first),

and reports each one's coefficient of variation and (max - min) / median. It is taken when a target
starts and when it writes meta.json (``timing_noise``: {start, end}), and the results index shows
the larger CV. It measures the host that writes the file; points measured on Dask workers carry
their own host in their rows. It does not count as a timing (:func:`tracer.measure.timing.timing_calls`).
"""
from __future__ import annotations

import numpy as np

#: bytes of the memory kernel's random cycle
MEM_BYTES = 8 << 20


def timing_noise(samples: int = 11, min_sample: float = 0.02) -> dict:
    """{clock, samples, compute_cv, compute_spread, memory_cv, memory_spread} of this host now."""
    import numba

    from tracer.measure.machine import LINE, _chase, _cycle
    from tracer.measure.timing import _probe_kernel, clock_name, default_clock, sample_calls
    if samples < 2:
        raise ValueError(f"timing_noise needs at least 2 samples, got {samples}")
    x = np.arange(1 << 16, dtype=np.float64)
    lines = MEM_BYTES // LINE
    nxt = _cycle(lines)
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        clock = default_clock()  # the one-thread clock (thread CPU time where it sees the kernels' work)
        out = {"clock": clock_name(), "samples": samples}
        for name, fn in (("compute", lambda: _probe_kernel(x, 4)), ("memory", lambda: _chase(nxt, 0, lines))):
            t = np.array(sample_calls(fn, samples, 1, min_sample, clock))
            out[f"{name}_cv"] = round(float(t.std(ddof=1) / t.mean()), 4)
            out[f"{name}_spread"] = round(float(np.ptp(t) / np.median(t)), 4)
    finally:
        numba.set_num_threads(threads)
    return out


def worst_cv(meta: dict) -> float | None:
    """The largest CV of a meta.json's ``timing_noise`` (start and end, both kernels); None without one."""
    tn = meta.get("timing_noise") or {}
    cvs = [v for part in tn.values() if isinstance(part, dict) for k, v in part.items() if k.endswith("_cv")]
    return max(cvs) if cvs else None
