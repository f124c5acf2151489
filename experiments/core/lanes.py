"""`all --jobs N`: the targets of `all` side by side, up to N at a time in N lane processes, each
target started once the targets whose outputs it reads have finished.

Every target measures with one Numba thread on the thread CPU clock, so on a machine of N cores
N targets can measure side by side: each is timed by its own thread's CPU time, and every time is a
ratio to a reference timed beside it in the same process, so what a neighbour on another core costs
(shared L3 and memory bandwidth, about 5 % on this 2-core EPYC host for the grid and the wide BVH)
hits a point and its reference alike. They share one point store: a point two targets need is
measured once (:meth:`experiments.core.store.PointStore.claim`).

A lane is one long-lived worker process (spawned, so it shares no threads or locks with this one) that
runs target after target in-process, as the serial `all` does: the imports and the loaded kernels
are paid once per lane, not once per target (26 start-ups were most of `all --quick`). A target's
output (file descriptors 1 and 2, so compiled code's writes too) goes to a file and is printed whole
when it finishes; a failed target does not stop the others, and a lane that dies (a crash in
compiled code) fails its target loudly and is replaced.

Among the targets ready to start, the longest first (their wall time in the last run's meta.json,
:func:`experiments.core.common.expected_seconds`), so the long ones do not end up alone at the end.

Targets in ``alone`` run with no neighbour: one starts only when no other target runs and no other
target is ready to start, and nothing starts beside it. Pairing a time with a reference timed
beside it cancels what a neighbour costs only when the neighbour costs both alike; ``alone`` holds
the targets where it does not (:data:`experiments.run.ALONE` says why for each): absolute times
compared across minutes (advise-check met its prediction goal on 7 of 16 rows beside another
target, on 10 of 16 alone; same kernels and host), and a kernel that a neighbour's memory traffic
slows more than its reference (the packets against Embree).
"""
from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import tempfile
import threading
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path


def longest_first(order: list[str], expected: dict) -> list[str]:
    """``order`` by ``expected`` seconds, largest first (ties: the serial order): the order in which
    ready targets are started."""
    return sorted(order, key=lambda t: (-expected.get(t, 0.0), order.index(t)))


def _ready(name: str, reads: dict, done: set, order: list[str]) -> bool:
    return all(d in done for d in reads.get(name, ()) if d in order)


def startable(pending: list[str], running: list[str], ready, alone=frozenset()) -> list[str]:
    """The targets of ``pending`` (in its order) that may start now, beside the ``running`` ones:
    the ready ones, except that a target of ``alone`` starts only into an empty machine when no
    other target is ready, and nothing starts beside one. The caller starts them while lanes are free."""
    if any(r in alone for r in running):
        return []
    ok = [t for t in pending if ready(t)]
    shared = [t for t in ok if t not in alone]
    if shared or running:
        return shared
    return ok[:1]


def _in_lane(main, argv: list[str], out: str, err: str) -> int:
    """One target in a lane process: ``main(argv)`` with file descriptors 1 and 2 sent to ``out`` and
    ``err`` for its duration (stderr is then no terminal, so the progress bars stay off)."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    with open(out, "w") as fo, open(err, "w") as fe:
        os.dup2(fo.fileno(), 1)
        os.dup2(fe.fileno(), 2)
        try:
            return int(main(argv) or 0)
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])


def _lane_start() -> None:
    """A lane ends with `all`: on Linux the kernel sends it SIGTERM when the process that started it
    exits, even killed, so no lane goes on measuring for a run that is gone."""
    try:
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: the SIGTERM handler of run_lanes still stops them
        pass


def _lanes(jobs: int) -> ProcessPoolExecutor:
    return ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_lane_start)


def _stop(signum, frame):
    raise SystemExit(128 + signum)


def run_lanes(order: list[str], reads: dict, argv_of, jobs: int, expected: dict | None = None, main=None,
              alone=frozenset()) -> dict:
    """Run ``main(argv_of(name))`` (default :func:`experiments.run.main`; a module-level function) for
    every target of ``order`` in ``jobs`` lane processes, each once its ``reads`` have finished
    (the targets of ``alone`` with no neighbour: :func:`startable`).
    Returns name -> exit status (1 for a target whose lane died). Each target's stdout and stderr
    are printed when it ends (stderr on stderr)."""
    if main is None:
        from experiments.run import main
    pending = longest_first(order, expected or {})
    running: dict = {}  # future -> (name, start time)
    done: set = set()
    status: dict[str, int] = {}
    started = time.time()
    # SIGTERM (a job scheduler, `kill`) unwinds like Ctrl-C, so the finally below stops the lanes
    old = signal.signal(signal.SIGTERM, _stop) if threading.current_thread() is threading.main_thread() else None
    pool = _lanes(jobs)
    with tempfile.TemporaryDirectory(prefix="gridcost-lanes-") as tmp:
        try:
            while pending or running:
                for name in startable(pending, [n for n, _ in running.values()],
                                      lambda t: _ready(t, reads, done, order), alone):
                    if len(running) >= jobs:
                        break
                    pending.remove(name)
                    fut = pool.submit(_in_lane, main, argv_of(name), *(str(Path(tmp) / f"{name}.{s}")
                                                                        for s in ("out", "err")))
                    running[fut] = (name, time.time())
                    print(f"all: {name} started ({time.time() - started:.0f} s)", file=sys.stderr, flush=True)
                if not running:  # nothing can start: a dependency outside `order` (never happens)
                    raise RuntimeError(f"all --jobs: no target can start: {pending}")
                finished, _ = wait(list(running), return_when=FIRST_COMPLETED)
                broken = False
                for fut in finished:
                    name, t0 = running.pop(fut)
                    done.add(name)
                    try:
                        status[name] = fut.result()
                    except BrokenProcessPool:
                        status[name], broken = 1, True
                        print(f"error: {name}: its lane process died (killed, or a crash in compiled code); "
                              "the other targets go on in a new lane", file=sys.stderr, flush=True)
                    except Exception as exc:  # main returns a status; this is the lane's own failure
                        status[name] = 1
                        print(f"internal error in {name}: {type(exc).__name__}: {exc}", file=sys.stderr, flush=True)
                    for s, stream in (("out", sys.stdout), ("err", sys.stderr)):
                        f = Path(tmp) / f"{name}.{s}"
                        stream.write(f.read_text(errors="replace") if f.exists() else "")
                    print(f"all: {name} finished, exit {status[name]}, {time.time() - t0:.0f} s "
                          f"({time.time() - started:.0f} s in)", file=sys.stderr, flush=True)
                if broken:  # a dead lane breaks the pool: what still ran there is requeued in a new one
                    for fut, (name, _) in running.items():
                        pending.insert(0, name)
                    running.clear()
                    pool.shutdown(wait=False, cancel_futures=True)
                    pool = _lanes(jobs)
        finally:
            if running:  # interrupted: the lanes stop with us, mid-target (its outputs are written atomically)
                print("all: stopped; " + ", ".join(n for n, _ in running.values()) + " did not finish (their "
                      "folders are as before the run; a rerun resumes from the stored points)", file=sys.stderr,
                      flush=True)
                for proc in list(getattr(pool, "_processes", {}).values()):
                    proc.terminate()
            pool.shutdown(wait=True, cancel_futures=True)
            if old is not None:
                signal.signal(signal.SIGTERM, old)
    return status
