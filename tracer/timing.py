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


def default_clock() -> Callable[[], float]:
    """The clock timings use: with one Numba thread the work runs on the calling thread, so its CPU
    time (``time.thread_time``) measures the work and not the waits of a shared, busy machine; with
    more threads, wall time (``time.perf_counter``). ``GRIDCOST_CLOCK=wall`` forces wall time."""
    import numba
    if os.environ.get("GRIDCOST_CLOCK", "") != "wall" and numba.get_num_threads() == 1:
        return time.thread_time
    return time.perf_counter


def clock_name() -> str:
    return "thread CPU time" if default_clock() is time.thread_time else "wall time"


def time_call(fn: Callable[[], object], repeats: int = 5, warmup: int = 1,
              min_sample: float = MIN_SAMPLE_SECONDS, clock: Callable[[], float] | None = None) -> Timing:
    """Call ``fn`` ``warmup`` times untimed (JIT compilation, caches), then take ``repeats`` samples;
    a sample runs ``fn`` back to back until it lasts ``min_sample`` seconds and is reported per call.
    ``clock`` defaults to :func:`default_clock`."""
    clock = clock or default_clock()
    for _ in range(warmup):
        fn()
    t0 = clock()
    fn()
    once = clock() - t0
    number = max(1, int(np.ceil(min_sample / max(once, 1e-9)))) if once < min_sample else 1
    runs = []
    for _ in range(max(1, repeats)):
        t0 = clock()
        for _ in range(number):
            fn()
        runs.append((clock() - t0) / number)
    return Timing(float(np.median(runs)), float(min(runs)), float(max(runs)), runs)


def time_paired(fns: dict, rounds: int = 7, repeats: int = 3, clock: Callable[[], float] | None = None,
                min_sample: float = MIN_SAMPLE_SECONDS) -> dict:
    """Time several callables in interleaved rounds (each round times every callable once with
    :func:`time_call`), so slow drifts of a shared machine hit all of them alike. Returns name ->
    list of per-round median seconds; compare callables by the median of per-round ratios
    (:func:`paired_ratio`), not by ratios of separately taken medians."""
    out = {k: [] for k in fns}
    for fn in fns.values():
        fn()  # warm-up (JIT compilation, caches) before the first round
    for _ in range(max(1, rounds)):
        for k, fn in fns.items():
            out[k].append(time_call(fn, repeats=repeats, warmup=0, clock=clock, min_sample=min_sample).median)
    return out


def paired_ratio(times: dict, a: str, b: str) -> tuple[float, float, float]:
    """Median, min and max over rounds of times[a] / times[b] (from :func:`time_paired`)."""
    r = np.asarray(times[a]) / np.asarray(times[b])
    return float(np.median(r)), float(r.min()), float(r.max())


def set_threads(n: int | None) -> int:
    """Use ``n`` Numba threads (all when None). With ``GRIDCOST_PIN=1`` the process is also pinned to
    the first ``n`` CPUs (off by default: on a shared machine pinning to a busy CPU hurts more than it
    helps; single-thread timings use the thread's CPU time instead). Returns the count."""
    import numba
    avail = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else list(range(os.cpu_count() or 1))
    total = numba.config.NUMBA_NUM_THREADS
    n = total if n is None else max(1, min(int(n), total))
    numba.set_num_threads(n)
    if hasattr(os, "sched_setaffinity") and os.environ.get("GRIDCOST_PIN") == "1":
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
            "python": platform.python_version(), "numba_threads": numba.get_num_threads(),
            "clock": clock_name(), "load_average": os.getloadavg() if hasattr(os, "getloadavg") else None}
