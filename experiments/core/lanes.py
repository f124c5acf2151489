"""`all --jobs N`: the targets of `all` as processes, up to N at a time, each started once the targets
whose outputs it reads have finished.

Every target measures with one Numba thread on the thread CPU clock, so on a machine of N cores
N targets can measure side by side: each is timed by its own thread's CPU time, and every time is a
ratio to a reference timed beside it in the same process, so what a neighbour on another core costs
(shared L3 and memory bandwidth, about 5 % on this 2-core EPYC host for the grid and the wide BVH)
hits a point and its reference alike. They share one point store: a point two targets need is
measured once (:meth:`experiments.core.store.PointStore.claim`).

Among the targets ready to start, the longest first (their wall time in the last run's meta.json,
:func:`experiments.core.common.expected_seconds`), so the long ones do not end up alone at the end.
A target's output is printed whole when it finishes; a failed target does not stop the others, as
in the serial `all`.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def longest_first(order: list[str], expected: dict) -> list[str]:
    """``order`` by ``expected`` seconds, largest first (ties: the serial order): the order in which
    ready targets are started."""
    return sorted(order, key=lambda t: (-expected.get(t, 0.0), order.index(t)))


def _ready(name: str, reads: dict, done: set, order: list[str]) -> bool:
    return all(d in done for d in reads.get(name, ()) if d in order)


def run_lanes(order: list[str], reads: dict, command_of, jobs: int, expected: dict | None = None) -> dict:
    """Run the command ``command_of(name)`` of every target of ``order`` (``python -m experiments.run
    <target> …``), at most ``jobs`` at a time, each once its ``reads`` have finished. Returns name ->
    exit status. Each child's stdout and stderr are printed when it ends (stderr on stderr)."""
    pending = longest_first(order, expected or {})
    running: dict[str, tuple] = {}
    done: set = set()
    status: dict[str, int] = {}
    started = time.time()
    with tempfile.TemporaryDirectory(prefix="gridcost-lanes-") as tmp:
        try:
            while pending or running:
                for name in [t for t in pending if _ready(t, reads, done, order)]:
                    if len(running) >= jobs:
                        break
                    pending.remove(name)
                    out, err = (open(Path(tmp) / f"{name}.{s}", "w+") for s in ("out", "err"))
                    proc = subprocess.Popen(command_of(name), stdout=out, stderr=err,
                                            env=dict(os.environ, TQDM_DISABLE="1"))
                    running[name] = (proc, out, err, time.time())
                    print(f"all: {name} started ({time.time() - started:.0f} s)", file=sys.stderr, flush=True)
                if not running:  # nothing can start: a dependency outside `order` (never happens)
                    raise RuntimeError(f"all --jobs: no target can start: {pending}")
                time.sleep(0.2)
                for name, (proc, out, err, t0) in list(running.items()):
                    if proc.poll() is None:
                        continue
                    del running[name]
                    done.add(name)
                    status[name] = proc.returncode
                    for f, stream in ((out, sys.stdout), (err, sys.stderr)):
                        f.seek(0)
                        stream.write(f.read())
                        f.close()
                    print(f"all: {name} finished, exit {proc.returncode}, {time.time() - t0:.0f} s "
                          f"({time.time() - started:.0f} s in)", file=sys.stderr, flush=True)
        finally:
            for proc, out, err, _ in running.values():  # interrupted: the children stop with us
                proc.terminate()
                proc.wait()
                out.close()
                err.close()
    return status
