"""The overall bar of ``all``: weighted by each target's last wall time of the same kind of run."""
from __future__ import annotations

import io
import json

from experiments.core.common import expected_seconds, overall_progress


def _meta(root, name, seconds, quick):
    (root / name).mkdir(parents=True)
    (root / name / "meta.json").write_text(json.dumps({"wall_seconds": seconds, "quick": quick}))


def test_expected_seconds_uses_the_same_kind_of_run(tmp_path):
    _meta(tmp_path, "a", 100.0, False)
    _meta(tmp_path, "b", 10.0, True)   # a quick run's time says nothing of a full one
    _meta(tmp_path, "c", 300.0, False)
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "meta.json").write_text("{broken")
    w = expected_seconds(tmp_path, ["a", "b", "c", "d"], quick=False)
    assert w["a"] == 100.0 and w["c"] == 300.0
    assert w["b"] == w["d"] == 300.0  # unknown: the median of the known ones (upper of two)
    assert expected_seconds(tmp_path, ["a", "b"], quick=True) == {"a": 10.0, "b": 10.0}
    assert expected_seconds(tmp_path / "none", ["x"], quick=False) == {"x": 60.0}


def test_overall_bar_advances_by_weight(monkeypatch):
    import tqdm
    buf = io.StringIO()
    real = tqdm.tqdm
    monkeypatch.setattr(tqdm, "tqdm", lambda *a, **k: real(*a, **{**k, "disable": False, "file": buf}))
    bar = overall_progress({"table2": 300.0, "fig2": 2.0})
    bar.start("table2")
    bar.advance("table2", "fig2")
    assert bar.n == 300 and bar.total == 302
    bar.advance("fig2")
    assert bar.n == 302
    bar.close()
    text = buf.getvalue()
    assert "running table2" in text and "next fig2" in text and "100%" in text
