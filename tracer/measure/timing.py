"""Fair timing: warm-up call first, then the median of >= 5 repeats; thread pinning."""
from __future__ import annotations

import functools
import os
import platform
import sys
import time
from typing import Callable, NamedTuple

import numpy as np
from numba import prange

from tracer.accel._jit import pjit


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


#: the thread clock is trusted when, on a known single-thread kernel (the best of five runs), it reads at
#: least this fraction of the process's CPU time or of wall time. A threading layer that runs the work on
#: a worker thread reads ~0.001 of both. Preemption on a machine with more runnable processes than cores
#: lowers the share of wall time (0.2-0.9 seen) but not the share of the process's CPU time, so a busy
#: machine does not flip the clock (the clock is part of every measurement key)
THREAD_CLOCK_MIN_RATIO = 0.5


@functools.lru_cache(maxsize=1)
def thread_clock_check() -> dict:
    """Once per process: does ``time.thread_time`` see the work of a one-thread ``prange`` kernel?
    Under a threading layer that runs ``prange`` work on a worker thread the calling thread's CPU
    time reads almost nothing, and every ratio against it would inflate. Returns {ok, ratio (of wall
    time), cpu_share (of the process's CPU time), wall, thread, process}: the best of five runs of
    :func:`_probe_kernel` (~60 ms each)."""
    import numba
    n = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        x = np.arange(1 << 16, dtype=np.float64)
        _probe_kernel(x, 1)
        best = (0.0, 0.0, 0.0, 0.0, 0.0)
        for _ in range(5):
            w0, c0, p0 = time.perf_counter(), time.thread_time(), time.process_time()
            _probe_kernel(x, 120)
            wall, cpu, proc = time.perf_counter() - w0, time.thread_time() - c0, time.process_time() - p0
            ratio, share = (cpu / wall if wall > 0 else 0.0), (cpu / proc if proc > 0 else 0.0)
            if max(ratio, share) > max(best[0], best[1]):
                best = (ratio, share, wall, cpu, proc)
    finally:
        numba.set_num_threads(n)
    return {"ok": max(best[0], best[1]) >= THREAD_CLOCK_MIN_RATIO, "ratio": round(best[0], 4),
            "cpu_share": round(best[1], 4), "wall": best[2], "thread": best[3], "process": best[4]}


@pjit
def _probe_kernel(x, reps):
    """A known amount of single-ray-like work through ``prange`` (as every batched kernel runs)."""
    acc = 0.0
    for th in prange(1):
        s = 0.0
        for _ in range(reps):
            for i in range(x.shape[0]):
                s += np.sqrt(x[i] + s * 1e-9)
        acc += s
    return acc


def _pin_setting() -> bool:
    from tracer.settings import current
    return current().pin


def default_clock() -> Callable[[], float]:
    """The clock timings use: with one Numba thread the work runs on the calling thread, so its CPU
    time (``time.thread_time``) measures the work and not the waits of a shared, busy machine --
    provided :func:`thread_clock_check` finds it does see a kernel's work; otherwise, and with more
    threads, wall time (``time.perf_counter``). ``GRIDCOST_CLOCK=wall`` forces wall time."""
    import numba
    from tracer.settings import current, run_log
    if current().clock == "wall" or numba.get_num_threads() != 1:
        return time.perf_counter
    chk = thread_clock_check()
    if not chk["ok"]:
        log = run_log()
        if not log.clock_warned:
            log.clock_warned = True
            print(f"gridcost: the thread CPU clock read {chk['ratio']:.1%} of wall time and {chk['cpu_share']:.1%} of "
                  "the process's CPU time on a one-thread kernel (work runs on another thread?); timing with wall "
                  "time instead", file=sys.stderr)
        return time.perf_counter
    return time.thread_time


def clock_name() -> str:
    return "thread CPU time" if default_clock() is time.thread_time else "wall time"


#: builds are timed with wall time: a library may build on its own threads, which the calling
#: thread's CPU time would not see
build_clock = time.perf_counter


def timing_calls() -> int:
    """How many :func:`time_call` timings this run has taken (lets the result writer tell a
    file measured now from one drawn from stored points)."""
    from tracer.settings import run_log
    return run_log().timings


def _count_timing() -> None:
    from tracer.settings import run_log
    run_log().timings += 1


def time_call(fn: Callable[[], object], repeats: int = 5, warmup: int = 1,
              min_sample: float = MIN_SAMPLE_SECONDS, clock: Callable[[], float] | None = None,
              number: int | None = None) -> Timing:
    """Call ``fn`` ``warmup`` times untimed (JIT compilation, caches), then take ``repeats`` samples;
    a sample runs ``fn`` back to back until it lasts ``min_sample`` seconds and is reported per call.
    ``clock`` defaults to :func:`default_clock`; ``number`` (calls per sample, from
    :func:`calls_per_sample`) skips the calibration call."""
    _count_timing()
    runs = sample_calls(fn, repeats, warmup, min_sample, clock, number)
    return Timing(float(np.median(runs)), float(min(runs)), float(max(runs)), runs)


def calls_per_sample(once: float, min_sample: float = MIN_SAMPLE_SECONDS) -> int:
    """Back-to-back calls that make a sample of at least ``min_sample`` seconds, for a call that took
    ``once`` seconds."""
    return max(1, int(np.ceil(min_sample / max(once, 1e-9)))) if once < min_sample else 1


def sample_calls(fn: Callable[[], object], repeats: int = 5, warmup: int = 1,
                 min_sample: float = MIN_SAMPLE_SECONDS, clock: Callable[[], float] | None = None,
                 number: int | None = None) -> list[float]:
    """:func:`time_call`'s samples (seconds per call), without counting as a timing of the run
    (the timing-noise meter, ``experiments.core.noise``, uses it so a file drawn from stored points
    is still told apart from one measured now)."""
    clock = clock or default_clock()
    for _ in range(warmup):
        fn()
    if number is None:
        t0 = clock()
        fn()
        number = calls_per_sample(clock() - t0, min_sample)
    runs = []
    for _ in range(max(1, repeats)):
        t0 = clock()
        for _ in range(number):
            fn()
        runs.append((clock() - t0) / number)
    return runs


def time_single_pass(trace: Callable, o: np.ndarray, d: np.ndarray, chunks: int = 1, warm: int = 0,
                     clock: Callable[[], float] | None = None) -> list[float]:
    """Per-ray seconds of tracing the rays ``o, d`` once with ``trace(o, d)``, the way an application
    traces its first rays (repeating the same few rays lets the caches and the branch predictor learn
    them: up to 2.5x too fast): the first ``warm`` rays are traced untimed (cold caches after a build),
    then each of ``chunks`` parts of the rest once, minus the per-call overhead (the median time of a
    1-ray call, floored at a quarter of the part's time). One value per part."""
    clock = clock or default_clock()
    _count_timing()
    o1, d1 = o[:1].copy(), d[:1].copy()
    trace(o1, d1)
    ov = []
    for _ in range(15):
        t0 = clock()
        trace(o1, d1)
        ov.append(clock() - t0)
    overhead = float(np.median(ov))
    warm = min(int(warm), len(o) - 1)
    if warm > 0:
        trace(o[:warm], d[:warm])
    per = []
    for part in np.array_split(np.arange(warm, len(o)), max(1, chunks)):
        po, pd_ = np.ascontiguousarray(o[part]), np.ascontiguousarray(d[part])
        t0 = clock()
        trace(po, pd_)
        dt = clock() - t0
        per.append(max(dt - overhead, 0.25 * dt) / max(len(part), 1))
    return per


def time_paired(fns: dict, rounds: int = 7, repeats: int = 3, clock: Callable[[], float] | None = None,
                min_sample: float = MIN_SAMPLE_SECONDS, more: Callable[[dict], bool] | None = None,
                max_rounds: int | None = None) -> dict:
    """Time several callables in interleaved rounds (each round times every callable once with
    :func:`time_call`), so slow drifts of a shared machine hit all of them alike. Returns name ->
    list of per-round median seconds; compare callables by the median of per-round ratios
    (:func:`paired_ratio`), not by ratios of separately taken medians. After ``rounds`` rounds,
    one more round is timed while ``more(times so far)`` is true, up to ``max_rounds`` in all; when
    ``more`` returns a collection of names, that round times only those of them still timed (a name
    once left out is never timed again, so every list holds the first rounds of the same sequence,
    and :func:`paired_ratio` compares two callables over the rounds both were timed in)."""
    out = {k: [] for k in fns}
    clock = clock or default_clock()
    number = {}
    for k, fn in fns.items():  # the warm-up (JIT compilation, caches), timed to size every round's samples
        fn()
        t0 = clock()
        fn()
        number[k] = calls_per_sample(clock() - t0, min_sample)
    limit = max(1, rounds) if more is None else max(1, rounds, max_rounds or 0)
    active = list(fns)
    for r in range(limit):
        if r >= max(1, rounds):
            want = more(out)
            if not want:
                break
            if want is not True:
                active = [k for k in active if k in want]
        for k in active:
            fn = fns[k]
            out[k].append(time_call(fn, repeats=repeats, warmup=0, clock=clock, min_sample=min_sample,
                                    number=number[k]).median)
    return out


def paired_ratio(times: dict, a: str, b: str) -> tuple[float, float, float]:
    """Median, min and max over rounds of times[a] / times[b] (from :func:`time_paired`; over the
    rounds both were timed in)."""
    r = common_ratio(times, a, b)
    return float(np.median(r)), float(r.min()), float(r.max())


def common_ratio(times: dict, a, b) -> np.ndarray:
    """Per-round times[a] / times[b] over the rounds both were timed in (:func:`time_paired` may
    stop timing some callables before others: the shorter list is a prefix of the same rounds)."""
    n = min(len(times[a]), len(times[b]))
    return np.asarray(times[a][:n], float) / np.asarray(times[b][:n], float)


def median_ci(x, level: float = 0.95) -> tuple[float, float]:
    """Distribution-free confidence interval of the median of ``x``: the order statistics whose
    binomial(n, 1/2) tail holds (1 - level)/2 each side (conservative; the whole range when n < 6)."""
    from scipy.stats import binom
    v = np.sort(np.asarray(x, float))
    n = len(v)
    k = int(binom.ppf((1.0 - level) / 2.0, n, 0.5))  # P(B < k) <= alpha/2 with B ~ binom(n, 1/2)
    lo = max(k - 1, 0)
    return float(v[lo]), float(v[n - 1 - lo])


def set_threads(n: int | None) -> int:
    """Use ``n`` Numba threads (all when None). With ``GRIDCOST_PIN=1`` the process is also pinned to
    the first ``n`` CPUs (off by default: on a shared machine pinning to a busy CPU hurts more than it
    helps; single-thread timings use the thread's CPU time instead). Returns the count."""
    import numba
    avail = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else list(range(os.cpu_count() or 1))
    total = numba.config.NUMBA_NUM_THREADS
    n = total if n is None else max(1, min(int(n), total))
    numba.set_num_threads(n)
    if hasattr(os, "sched_setaffinity") and _pin_setting():
        try:
            all_cpus = set(range(os.cpu_count() or 1))
            os.sched_setaffinity(0, set(avail[:n]) if n < total else all_cpus)
        except OSError:
            pass
    return n


def measurement_key(code_paths: tuple[str, ...] = ()) -> dict:
    """:func:`tracer.measure.provenance.measurement_key` of a measurement made now: this process's Numba
    thread count and clock (:func:`clock_name`)."""
    import numba

    from tracer.measure import provenance
    return provenance.measurement_key(tuple(code_paths), numba.get_num_threads(), clock_name())


def host_info() -> dict:
    import numba

    from tracer.accel.pages import thp_mode
    from tracer.measure.provenance import cpu_model, host
    return {"host": host(), "cpu": cpu_model(), "cores": os.cpu_count(), "machine": platform.machine(),
            "python": platform.python_version(), "numba_threads": numba.get_num_threads(),
            "clock": clock_name(), "thread_clock_check": thread_clock_check(),
            # whether the structures' arrays (and Embree's) can be on huge pages (tracer.accel.pages)
            "transparent_huge_pages": thp_mode(),
            "load_average": os.getloadavg() if hasattr(os, "getloadavg") else None}
