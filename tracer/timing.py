"""Fair timing: warm-up call first, then the median of >= 5 repeats; thread pinning."""
from __future__ import annotations

import os
import platform
import time
from typing import Callable, NamedTuple

import numpy as np


class Timing(NamedTuple):
    median: float
    min: float
    max: float
    runs: list

    @property
    def spread(self) -> float:
        """(max - min) / median: how noisy the repeats were."""
        return (self.max - self.min) / self.median if self.median > 0 else 0.0


#: a timed sample shorter than this is made of several back-to-back calls (like timeit's autorange)
MIN_SAMPLE_SECONDS = 0.02


def time_call(fn: Callable[[], object], repeats: int = 5, warmup: int = 1,
              min_sample: float = MIN_SAMPLE_SECONDS) -> Timing:
    """Call ``fn`` ``warmup`` times untimed (JIT compilation, caches), then take ``repeats`` samples;
    a sample runs ``fn`` back to back until it lasts ``min_sample`` seconds and is reported per call."""
    for _ in range(warmup):
        fn()
    t0 = time.perf_counter()
    fn()
    once = time.perf_counter() - t0
    number = max(1, int(np.ceil(min_sample / max(once, 1e-9)))) if once < min_sample else 1
    runs = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        runs.append((time.perf_counter() - t0) / number)
    return Timing(float(np.median(runs)), float(min(runs)), float(max(runs)), runs)


def set_threads(n: int | None) -> int:
    """Use ``n`` Numba threads, pinned to the first ``n`` CPUs (all when None). Returns the count."""
    import numba
    avail = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else list(range(os.cpu_count() or 1))
    total = numba.config.NUMBA_NUM_THREADS
    n = total if n is None else max(1, min(int(n), total))
    numba.set_num_threads(n)
    if hasattr(os, "sched_setaffinity"):
        try:
            all_cpus = set(range(os.cpu_count() or 1))
            os.sched_setaffinity(0, set(avail[:n]) if n < total else all_cpus)
        except OSError:
            pass
    return n


def host_info() -> dict:
    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    import numba
    return {"cpu": cpu, "cores": os.cpu_count(), "machine": platform.machine(),
            "python": platform.python_version(), "numba_threads": numba.get_num_threads()}
