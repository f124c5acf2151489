"""The machine model of this host: cache sizes and the latency of a dependent load for a working
set of B bytes, measured once by a pointer-chasing probe and cached per host.

The probe (:func:`chase_ns`) builds one random cycle through the cache lines of a buffer of B
bytes (Sattolo's algorithm, one 8-byte pointer per 64-byte line) and follows it: every load
depends on the one before, so its time is the latency of the level the buffer lives in (with the
TLB misses a random walk over B bytes brings). A sequential sum over the same buffer gives the
bandwidth. Sizes run from 4 KiB to ``max_bytes`` in steps of sqrt(2).

``latency_ns(B)`` interpolates the measured curve in log B; ``extra_ns(B)`` is what a load at
working set B costs over one that hits L1 — the quantity the memory-aware cost model
(:mod:`costmodel.memory`) charges per cell visit. Cache sizes come from sysfs
(:func:`tracer.measure.memory.cache_bytes`).

The measured curve is stored in ``~/.cache/gridcost/machine/<host>-<cpu digest>.json`` (override
the folder with $GRIDCOST_MACHINE_DIR) with the host, CPU, time and probe settings; a stored curve
of another CPU is never used (the file name carries the CPU), and ``refresh=True`` re-measures.
"""
from __future__ import annotations

import hashlib
import json
import sys
import time
from pathlib import Path

import numpy as np

from tracer.accel._jit import jit
from tracer.measure.memory import cache_bytes
from tracer.measure.provenance import cpu_model, host, host_cpu_features
from tracer.measure.timing import clock_name, default_clock
from tracer.storage import atomic_write

LINE = 64
#: default probe range: 4 KiB .. 128 MiB (well past any L3 of this class of machine)
MIN_BYTES, MAX_BYTES = 4 << 10, 128 << 20
PROBE_VERSION = 1


@jit
def _chase(nxt, start, steps):
    i = start
    for _ in range(steps):
        i = nxt[i]
    return i


@jit
def _stream(buf):
    s = 0
    for i in range(buf.shape[0]):
        s += buf[i]
    return s


def _cycle(n_lines: int, seed: int = 0) -> np.ndarray:
    """int64 array of n_lines * 8 slots whose line-start slots form one random cycle (Sattolo)."""
    rng = np.random.default_rng(seed)
    perm = rng.permutation(n_lines)
    nxt = np.zeros(n_lines * (LINE // 8), np.int64)
    step = LINE // 8
    nxt[perm * step] = np.roll(perm, -1) * step
    return nxt


def chase_ns(nbytes: int, accesses: int = 2_000_000, repeats: int = 3) -> float:
    """Median ns per dependent load over a working set of ``nbytes`` (after one warm pass)."""
    n_lines = max(2, int(nbytes) // LINE)
    nxt = _cycle(n_lines)
    _chase(nxt, 0, n_lines)  # warm: touch every line once (and compile)
    clock, times = default_clock(), []
    for _ in range(repeats):
        t0 = clock()
        _chase(nxt, 0, accesses)
        times.append(clock() - t0)
    return float(np.median(times)) / accesses * 1e9


def stream_gbs(nbytes: int, repeats: int = 3) -> float:
    """Median GB/s of a sequential int64 sum over ``nbytes``."""
    buf = np.ones(max(1, int(nbytes) // 8), np.int64)
    _stream(buf)
    reps = max(repeats, int(64e6 // max(nbytes, 1)))
    clock, times = default_clock(), []
    for _ in range(repeats):
        t0 = clock()
        for _ in range(max(1, reps // repeats)):
            _stream(buf)
        times.append((clock() - t0) / max(1, reps // repeats))
    return buf.nbytes / float(np.median(times)) / 1e9


def doubles_per_vector() -> int:
    """float64 lanes in one vector register of this CPU (:func:`tracer.measure.provenance.host_cpu_features`):
    8 with AVX-512, 4 with AVX, else the SSE2 width every x86-64 has, 2 (the packet test's
    ``<8 x double>`` takes 8 / this many instructions)."""
    f = host_cpu_features()
    return 8 if "avx512f" in f else (4 if "avx" in f else 2)


def machine_dir() -> Path:
    from tracer.settings import current
    env = current().machine_dir
    return Path(env) if env else Path.home() / ".cache" / "gridcost" / "machine"


def machine_file(quick: bool = False) -> Path:
    cpu = hashlib.sha256(cpu_model().encode()).hexdigest()[:12]
    return machine_dir() / f"{host()}-{cpu}{'-quick' if quick else ''}.json"


def probe(max_bytes: int = MAX_BYTES, accesses: int = 2_000_000) -> dict:
    """Measure the latency and bandwidth curves (about 20 s on a quiet 2-core machine)."""
    sizes = np.unique(np.round(np.geomspace(MIN_BYTES, max_bytes,
                                            int(2 * np.log2(max_bytes / MIN_BYTES)) + 1) / LINE) * LINE).astype(int)
    t0 = time.time()
    lat = [chase_ns(int(b), accesses) for b in sizes]
    bw = [stream_gbs(int(b)) for b in sizes]
    return {"version": PROBE_VERSION, "host": host(), "cpu": cpu_model(), "measured_at": time.time(),
            "probe_seconds": time.time() - t0, "accesses": accesses, "clock": clock_name(),
            "caches": {f"L{lv}": cache_bytes(lv) for lv in (1, 2, 3)},
            "max_bytes": int(max_bytes), "bytes": [int(b) for b in sizes], "latency_ns": lat, "bandwidth_gbs": bw}


class MachineModel:
    """Latency of a dependent load as a function of the working set, for this host.

    ``MachineModel.load()`` reads the cached probe of this host and CPU or measures it (and stores it
    atomically). ``latency_ns(B)``, ``extra_ns(B)`` (over an L1 hit) and ``level_latencies()``
    (the plateau of each cache level and DRAM) are what the cost model uses.
    """

    def __init__(self, data: dict):
        self.data = data
        self.bytes_ = np.asarray(data["bytes"], float)
        # a working set never loads faster than a smaller one: the curve made non-decreasing (the
        # probe's noise, and DRAM pages that happen to be close, can dip it)
        self.latency_ = np.maximum.accumulate(np.asarray(data["latency_ns"], float))
        self.caches_ = {k: int(v) for k, v in data["caches"].items()}

    @classmethod
    def load(cls, refresh: bool = False, quick: bool = False, log=None) -> "MachineModel":
        """The cached probe of this host, or a new one; ``quick`` (tests, --quick runs): up to 32 MiB,
        200k loads per size, stored apart from the full probe."""
        path = machine_file(quick)
        if path.is_file() and not refresh:
            try:
                data = json.loads(path.read_text())
            except (OSError, ValueError) as exc:  # a cut or garbled probe file is probed again, not fatal
                print(f"gridcost: the machine probe {path} is unreadable ({type(exc).__name__}); probing again",
                      file=sys.stderr)
                data = {}
            if isinstance(data, dict) and data.get("version") == PROBE_VERSION and data.get("cpu") == cpu_model():
                return cls(data)
        if log:
            log(f"machine model: probing load latency over 4 KiB .. {MAX_BYTES >> 20} MiB (once per host, ~20 s)")
        data = probe(32 << 20, 200_000) if quick else probe()
        data["quick"] = quick
        atomic_write(path, json.dumps(data, indent=1), strict=False)
        return cls(data)

    def latency_ns(self, nbytes):
        """Load latency (ns) at working set ``nbytes``: the curve interpolated in log B, flat beyond its ends."""
        return np.interp(np.log(np.maximum(np.asarray(nbytes, float), 1.0)), np.log(self.bytes_), self.latency_)

    def extra_ns(self, nbytes):
        """What a load at working set ``nbytes`` costs over an L1 hit (ns, >= 0)."""
        return np.maximum(self.latency_ns(nbytes) - self.latency_[0], 0.0)

    def level_latencies(self) -> dict:
        """Plateau latency (ns) of L1, L2, L3 and DRAM: the curve at half of each cache's size, and at
        the largest size probed for DRAM."""
        out = {f"L{lv}": float(self.latency_ns(self.caches_[f"L{lv}"] / 2)) for lv in (1, 2, 3)
               if self.caches_[f"L{lv}"] / 2 < self.bytes_[-1]}
        out["largest probed"] = float(self.latency_[-1])
        return out

    def summary(self) -> str:
        lat = self.level_latencies()
        return (f"{self.data['cpu']} on {self.data['host']}: caches "
                + ", ".join(f"{k} {v >> 10} KiB" for k, v in self.caches_.items())
                + "; load latency " + ", ".join(f"{k} {v:.1f} ns" for k, v in lat.items()))
