"""`all --jobs`: targets side by side in processes, each after the targets it reads, and a point two
targets need measured once (PointStore.claim)."""
from __future__ import annotations

import json
import os
import signal
import sys
import threading
import time

import pytest

from experiments.core.lanes import longest_first, run_lanes, startable
from experiments.core.store import PointStore


def stand_in(argv):
    """A stand-in target's main (module-level: lanes are spawned processes): argv = [name, seconds,
    log dir, exit status]; writes its start and end times and its lane's pid, sleeps, returns the status;
    status -9 kills its lane instead."""
    name, seconds, log_dir, rc = argv[0], float(argv[1]), argv[2], int(argv[3])
    t0 = time.time()
    time.sleep(seconds)
    print(f"out of {name}")
    if rc == -9:
        os._exit(9)
    with open(os.path.join(log_dir, name), "w") as f:
        f.write(json.dumps([t0, time.time(), os.getpid()]))
    return rc


def test_targets_start_after_what_they_read_and_at_most_jobs_at_once(tmp_path, capsys):
    seconds = {"a": 0.6, "b": 0.2, "c": 0.2, "d": 0.1, "e": 0.1}
    reads = {"c": ("a",), "d": ("a", "b", "c")}
    status = run_lanes(list(seconds), reads, lambda n: [n, str(seconds[n]), str(tmp_path), "3" if n == "b" else "0"],
                       jobs=2, expected={"a": 10, "b": 1, "c": 1, "d": 1}, main=stand_in)
    assert status == {"a": 0, "b": 3, "c": 0, "d": 0, "e": 0}  # a failed target does not stop the others
    span = {k: json.loads((tmp_path / k).read_text()) for k in seconds}
    assert span["c"][0] >= span["a"][1]
    assert span["d"][0] >= max(span[k][1] for k in "abc")
    assert span["b"][0] < span["a"][1]  # b did not wait for a: two at a time
    for t in span:  # never three at once
        assert sum(s <= span[t][0] < e for s, e, _ in span.values()) <= 2
    # two lane processes ran all five targets (no process per target), none of them this one
    assert len({pid for _, _, pid in span.values()}) == 2 and os.getpid() not in {p for _, _, p in span.values()}
    out = capsys.readouterr()
    assert out.out.count("out of") == 5 and "all: e finished, exit 0" in out.err


def test_a_target_that_runs_alone_has_no_neighbour(tmp_path):
    """advise-check's probe and truth are absolute times minutes apart: nothing runs beside it."""
    seconds = {"long": 0.6, "lone": 0.3, "b": 0.2, "c": 0.2, "last": 0.1}
    reads = {"last": ("lone",)}
    status = run_lanes(list(seconds), reads, lambda n: [n, str(seconds[n]), str(tmp_path), "0"], jobs=2,
                       expected={"lone": 100, "long": 10}, main=stand_in, alone={"lone"})
    assert set(status.values()) == {0}
    span = {k: json.loads((tmp_path / k).read_text()) for k in seconds}
    s, e, _ = span["lone"]
    for k, (s2, e2, _) in span.items():  # no other target's run overlaps lone's
        assert k == "lone" or e2 <= s or s2 >= e, (k, span)
    # longest first would have started lone first; it waited for the targets that could share the machine
    assert s >= max(span[k][1] for k in ("long", "b", "c")) and span["last"][0] >= e


def test_startable_keeps_lone_targets_for_an_empty_machine():
    ready = lambda t: t != "blocked"  # noqa: E731
    assert startable(["lone", "a", "b"], [], ready, {"lone"}) == ["a", "b"]
    assert startable(["lone", "blocked"], ["a"], ready, {"lone"}) == []  # a still runs
    assert startable(["lone", "blocked"], [], ready, {"lone"}) == ["lone"]
    assert startable(["a"], ["lone"], ready, {"lone"}) == []  # nothing beside it
    assert startable(["lone", "lone2"], [], ready, {"lone", "lone2"}) == ["lone"]  # one at a time
    assert startable(["a", "b"], ["c"], ready) == ["a", "b"]


def test_a_lane_that_dies_fails_its_target_loudly_and_the_rest_go_on(tmp_path, capsys):
    seconds = {"crash": 0.1, "after": 0.1, "then": 0.1}
    status = run_lanes(list(seconds), {"after": ("crash",)},
                       lambda n: [n, str(seconds[n]), str(tmp_path), "-9" if n == "crash" else "0"], jobs=1,
                       main=stand_in)
    assert status == {"crash": 1, "after": 0, "then": 0}
    assert "error: crash: its lane process died" in capsys.readouterr().err
    assert (tmp_path / "after").exists() and (tmp_path / "then").exists()


def test_longest_first_keeps_the_serial_order_on_ties():
    assert longest_first(["x", "y", "z", "w"], {"x": 1, "y": 5, "z": 1, "w": 9}) == ["w", "y", "x", "z"]


def test_a_point_claimed_by_one_target_is_measured_once(tmp_path):
    """Two targets (threads here: flock locks conflict between open files of one process too) need
    the same point: the second waits while the first measures, then reads its value."""
    spec = {"scene": "s", "params": {"cells": 8}}
    measured = []

    def target(tag, delay):
        store = PointStore(tmp_path)
        time.sleep(delay)
        with store.claim(spec):
            if store.get(spec) is None:
                time.sleep(0.3)
                measured.append(tag)
                store.put(spec, {"by": tag})
        return store.get(spec)

    threads = [threading.Thread(target=target, args=(t, d)) for t, d in (("first", 0.0), ("second", 0.05))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert measured == ["first"]
    assert PointStore(tmp_path).get(spec) == {"by": "first"}


@pytest.mark.parametrize("argv, says", [(["all", "--jobs", "999"], "--jobs must be between 1 and"),
                                        (["all", "--jobs", "2", "--threads", "2"], "not with --dask or --threads")])
def test_jobs_out_of_range_or_with_threads_is_refused(argv, says, capsys, tmp_path):
    from experiments.run import main
    import os
    cpus = len(os.sched_getaffinity(0))
    if cpus < 2 and "--threads" in argv:
        pytest.skip("one CPU: --jobs 2 is refused by its range first")
    assert main(argv + ["--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "r").exists()


def test_what_a_target_reads_is_a_target_of_all_that_runs_before_it():
    """`all --jobs` orders targets by READS alone: every name there is in ALL_ORDER, before its reader
    (the serial order, which the targets were written against, agrees)."""
    from experiments.run import ALL_ORDER, READS
    for target, reads in READS.items():
        assert target in ALL_ORDER
        for r in reads:
            assert ALL_ORDER.index(r) < ALL_ORDER.index(target), (target, r)


def sleeper(argv):
    """A stand-in target that writes its lane's pid at once, then sleeps ``argv[2]`` seconds."""
    with open(os.path.join(argv[1], argv[0]), "w") as f:
        f.write(str(os.getpid()))
    time.sleep(float(argv[2]))
    return 0


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.mark.parametrize("sig, status", [(signal.SIGTERM, 128 + signal.SIGTERM), (signal.SIGKILL, -signal.SIGKILL)])
def test_lanes_stop_with_the_run(tmp_path, sig, status):
    """`all --jobs` stopped by a scheduler (SIGTERM) or killed outright (SIGKILL): no lane goes on
    measuring for a run that is gone."""
    import subprocess
    code = (f"import sys; sys.path.insert(0, {os.path.dirname(__file__)!r}); from test_lanes import sleeper; "
            f"from experiments.core.lanes import run_lanes; "
            f"run_lanes(['a', 'b'], {{}}, lambda n: [n, {str(tmp_path)!r}, '60'], 2, main=sleeper)")
    run = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 60
    while not all((tmp_path / n).exists() and (tmp_path / n).read_text() for n in "ab"):
        assert time.time() < deadline and run.poll() is None
        time.sleep(0.1)
    pids = [int((tmp_path / n).read_text()) for n in "ab"]
    run.send_signal(sig)
    assert run.wait(timeout=30) == status
    if sig == signal.SIGTERM:  # one line names what did not finish
        assert "all: stopped; a, b did not finish" in run.stderr.read()
    deadline = time.time() + 10
    while any(_alive(p) for p in pids) and time.time() < deadline:
        time.sleep(0.1)
    assert not any(_alive(p) for p in pids)


def test_the_targets_that_run_alone_are_targets_of_all():
    from experiments.run import ALL_ORDER, ALONE
    assert ALONE and ALONE <= set(ALL_ORDER)
