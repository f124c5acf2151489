"""`all --jobs`: targets side by side in processes, each after the targets it reads, and a point two
targets need measured once (PointStore.claim)."""
from __future__ import annotations

import json
import sys
import threading
import time

import pytest

from experiments.core.lanes import longest_first, run_lanes
from experiments.core.store import PointStore


def _command(log_dir, seconds: dict, fail=()):
    """A stand-in target: writes its start and end times, sleeps, exits 3 when in ``fail``."""
    def command_of(name):
        code = (f"import json, time; t0 = time.time(); time.sleep({seconds[name]}); "
                f"open({str(log_dir / name)!r}, 'w').write(json.dumps([t0, time.time()])); "
                f"print('out of {name}'); raise SystemExit({3 if name in fail else 0})")
        return [sys.executable, "-c", code]
    return command_of


def test_targets_start_after_what_they_read_and_at_most_jobs_at_once(tmp_path, capsys):
    seconds = {"a": 0.6, "b": 0.2, "c": 0.2, "d": 0.1}
    reads = {"c": ("a",), "d": ("a", "b", "c")}
    status = run_lanes(list(seconds), reads, _command(tmp_path, seconds, fail={"b"}), jobs=2,
                       expected={"a": 10, "b": 1, "c": 1, "d": 1})
    assert status == {"a": 0, "b": 3, "c": 0, "d": 0}  # a failed target does not stop the others
    span = {k: json.loads((tmp_path / k).read_text()) for k in seconds}
    assert span["c"][0] >= span["a"][1]
    assert span["d"][0] >= max(span[k][1] for k in "abc")
    assert span["b"][0] < span["a"][1]  # b did not wait for a: two at a time
    for t in span:  # never three at once
        assert sum(s <= span[t][0] < e for s, e in span.values()) <= 2
    assert capsys.readouterr().out.count("out of") == 4


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
