"""Interrupts and unwritable outputs: one line on stderr, a distinct exit status, the output as it was
before the run; a run killed outright is put back by the next one; the parser's own errors are one line."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from experiments.core.store import OutputGuard
from experiments.run import Interrupted, main

REPO = Path(__file__).resolve().parents[1]


def _derive_folder(tmp_path):
    out = tmp_path / "out"
    (out / "derive").mkdir(parents=True)
    (out / "derive" / "summary.md").write_text("the committed summary\n")
    return out


@pytest.mark.parametrize("how, rc, word", [("ctrl-c", 130, "interrupted"), ("sigterm", 143, "terminated")])
def test_an_interrupted_run_says_one_line_and_leaves_the_output_as_it_was(how, rc, word, tmp_path, monkeypatch,
                                                                        capsys):
    out = _derive_folder(tmp_path)
    from tracer import storage
    real = storage.atomic_write

    def stop(path, data, **kw):
        if str(path).endswith("summary.md"):
            if how == "sigterm":  # the real signal, through the handler main installs
                os.kill(os.getpid(), signal.SIGTERM)
            raise KeyboardInterrupt
        return real(path, data, **kw)

    monkeypatch.setattr("experiments.ize.derive.atomic_write", stop)
    before = signal.getsignal(signal.SIGTERM)
    assert main(["derive", "--out", str(out)]) == rc
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and word in err[0] and "resumes" in err[0], err
    assert [p.name for p in (out / "derive").iterdir()] == ["summary.md"]
    assert (out / "derive" / "summary.md").read_text() == "the committed summary\n"
    assert not list(out.glob(".derive.before"))
    assert signal.getsignal(signal.SIGTERM) is before  # main puts the old handler back


def test_sigterm_raises_interrupted():
    from experiments.run import _on_term
    with pytest.raises(Interrupted):
        _on_term(signal.SIGTERM, None)
    assert issubclass(Interrupted, KeyboardInterrupt)


def test_a_run_killed_outright_is_put_back_by_the_next(tmp_path, capsys):
    """SIGKILL runs no handler: the snapshot stays, and the next run's guard puts it back first."""
    folder, figs = tmp_path / "out" / "t", tmp_path / "figs"
    folder.mkdir(parents=True)
    figs.mkdir()
    (folder / "a.csv").write_text("old\n")
    (figs / "t.png").write_text("old fig\n")
    (figs / "other.png").write_text("not this target's\n")
    OutputGuard(folder, figs, "t").__enter__()  # ... and the process dies before __exit__
    new = folder / "a.csv.tmp"
    new.write_text("half new\n")
    os.replace(new, folder / "a.csv")  # atomic writes: a new inode, the snapshot keeps the old one
    (folder / "b.csv").write_text("new\n")
    (figs / "t.svg").write_text("new fig\n")
    (figs / "t.png").unlink()
    with OutputGuard(folder, figs, "t"):
        assert sorted(p.name for p in folder.iterdir()) == ["a.csv"]
        assert (folder / "a.csv").read_text() == "old\n"
        assert sorted(p.name for p in figs.iterdir()) == ["other.png", "t.png"]
        assert (figs / "t.png").read_text() == "old fig\n"
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "put back" in err[0] and str(folder) in err[0], err
    assert not (tmp_path / "out" / ".t.before").exists()


def test_a_folder_another_live_run_is_writing_is_refused(tmp_path):
    """Two runs of one target on one folder: the second refuses (exit 2) rather than put back the
    first one's snapshot under it."""
    import json
    from tracer.errors import GridcostError
    folder = tmp_path / "t"
    folder.mkdir()
    (folder / "a.csv").write_text("being written\n")
    keep = tmp_path / ".t.before"
    keep.mkdir()
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (keep / "complete").write_text(json.dumps({"folder": False, "figs": [], "pid": other.pid,
                                                   "host": __import__("socket").gethostname()}))
        with pytest.raises(GridcostError, match=f"another gridcost run \\(pid {other.pid}\\)"):
            OutputGuard(folder).__enter__()
        assert (folder / "a.csv").read_text() == "being written\n" and (keep / "complete").exists()
    finally:
        other.kill()
        other.wait()
    with OutputGuard(folder):  # its maker gone: put back (no folder before it), then guarded again
        assert not folder.exists()


def test_a_guard_that_finished_leaves_no_snapshot_to_put_back(tmp_path, capsys):
    folder = tmp_path / "t"
    folder.mkdir()
    (folder / "a.csv").write_text("old\n")
    with OutputGuard(folder):
        (folder / "a.csv").unlink()
        (folder / "a.csv").write_text("new\n")
    with OutputGuard(folder):
        pass
    assert (folder / "a.csv").read_text() == "new\n" and capsys.readouterr().err == ""


def test_an_output_path_that_is_a_file_exits_2_in_one_line(tmp_path, capsys):
    blocker = tmp_path / "afile"
    blocker.write_text("mine\n")
    assert main(["derive", "--quick", "--out", str(blocker)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Not a directory" in err[0] and "--out" in err[0], err
    assert blocker.read_text() == "mine\n"


@pytest.mark.parametrize("argv, words", [(["nosuch"], "invalid choice"),
                                         (["derive", "--threads", "nan"], "invalid int value"),
                                         (["wald-lowres", "--sides", "0,-4"], "image sides between 1 and"),
                                         (["wald-lowres", "--sides", "abc"], "image sides between 1 and"),
                                         (["fig5", "--scenes", "bunny-948"], "name:compact|skinny")])
def test_the_parser_refuses_in_one_line(argv, words, capsys):
    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1 and words in err[0], err


def test_a_bad_environment_setting_exits_2_in_one_line(tmp_path):
    """GRIDCOST_* settings are read when the targets are imported, before the run's own error handling."""
    env = {**os.environ, "GRIDCOST_CLOCK": "bogus"}
    r = subprocess.run([sys.executable, "-m", "experiments.run", "derive", "--quick", "--out", str(tmp_path / "o")],
                       cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and "GRIDCOST_CLOCK" in err[0], r.stderr
    assert not (tmp_path / "o").exists()
