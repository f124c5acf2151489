"""The distributed sweep's guard: addresses refused, certificates written for their owner only."""
from __future__ import annotations

import stat

import pytest

from experiments.core.tls import check_address
from tracer.errors import GridcostError


@pytest.mark.parametrize("address", ["tcp://10.0.0.5:8786", "tcp://node1:8786", "10.0.0.5:8786"])
def test_plain_tcp_beyond_loopback_is_refused_unless_insecure(address):
    with pytest.raises(GridcostError, match="anyone who reaches the port"):
        check_address(address, None, insecure=False)
    check_address(address, None, insecure=True)


@pytest.mark.parametrize("address", ["tcp://127.0.0.1:8786", "tcp://localhost:8786", "tcp://[::1]:8786"])
def test_loopback_tcp_is_allowed(address):
    check_address(address, None, insecure=False)


def test_tls_needs_certificates_and_other_protocols_are_refused():
    with pytest.raises(GridcostError, match="needs --tls"):
        check_address("tls://node1:8786", None, insecure=False)
    check_address("tls://node1:8786", "/some/dir", insecure=False)
    with pytest.raises(GridcostError, match="unknown scheduler protocol"):
        check_address("ws://node1:8786", None, insecure=True)


def test_certs_target_writes_owner_only_files(tmp_path, capsys):
    pytest.importorskip("cryptography")
    from experiments.run import main
    assert main(["certs", "--dir", str(tmp_path / "tls"), "--hosts", "node1,10.0.0.5"]) == 0
    names = sorted(p.name for p in (tmp_path / "tls").iterdir())
    assert names == ["ca-key.pem", "ca.pem", "node-key.pem", "node.pem"]
    for p in (tmp_path / "tls").iterdir():
        assert stat.S_IMODE(p.stat().st_mode) == 0o600, p
    from cryptography import x509
    cert = x509.load_pem_x509_certificate((tmp_path / "tls" / "node.pem").read_bytes())
    sans = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert "node1" in sans.get_values_for_type(x509.DNSName)
    assert "dask scheduler --protocol tls" in capsys.readouterr().out


def test_a_plain_scheduler_on_the_network_is_refused_by_the_cli(capsys, tmp_path):
    pytest.importorskip("dask.distributed")
    from experiments.run import main
    assert main(["table2", "--quick", "--dask", "tcp://192.0.2.1:8786", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--insecure" in err[0], err


_TLS_SWEEP = r"""
import json, os, sys
STRANGER = '''
import json, sys
from dask.distributed import Client
refused = []
for addr in (sys.argv[1].replace("tls://", "tcp://"), sys.argv[1]):
    try:
        c = Client(addr, timeout=5)
        c.submit(sum, [1, 2]).result(timeout=5)
        refused.append(False)
    except Exception:
        refused.append(True)
print(json.dumps(refused))
'''
if __name__ == "__main__":
    os.environ["GRIDCOST_CLOCK"] = "wall"  # what DaskExecutor sets: the clock of a Dask run
    from experiments.core.context import RunContext
    from experiments.core.executor import DaskExecutor
    from experiments.core.sweep import sweep
    from experiments.core.tls import make_certs
    from tracer.scenes.rays import make_rays
    from tracer.scenes.scene import load_scene
    out = sys.argv[1]
    scene = load_scene("bunny-948")
    rays = {"random": make_rays(scene, "random", 2000, seed=0), "camera": make_rays(scene, "camera", 1500, seed=1)}
    params = [{"cells": 1000.0}, {"cells": 4000.0}, {"cells": 16000.0}]
    local = sweep(scene, "grid", params, rays, RunContext(out=out + "/local", threads=1).store(), 1)
    make_certs(out + "/tls")
    ctx = RunContext(out=out + "/dask", threads=1)
    ex = DaskExecutor("local", ctx, tls=out + "/tls")
    ctx.executor = ex
    try:
        address = ex.cluster.scheduler_address
        remote = sweep(scene, "grid", params, rays, ctx.store(), 1)
        # a stranger (another process, no certificate) tries plain TCP and TLS without a key
        import subprocess
        stranger = subprocess.run([sys.executable, "-c", STRANGER, address], capture_output=True, text=True,
                                  timeout=120)
        refused = json.loads(stranger.stdout.strip().splitlines()[-1])
    finally:
        ex.close()
    keys = ("param_cells", "cells", "refs", "steps", "tests", "setups", "hits", "ray_kind", "rays", "seed")
    print(json.dumps({"address": address, "refused": refused, "local": [[r[k] for k in keys] for r in local],
                      "remote": [[r[k] for k in keys] for r in remote],
                      "remote_ok": [bool(r["seconds_raw"] > 0 and r["worker"] and r["commit"]) for r in remote]}))
"""


def test_dask_two_process_tls_cluster_equals_local_and_refuses_strangers(tmp_path):
    """A TLS LocalCluster of two worker processes (one thread each, certificates from make_certs,
    as `gridcost certs` writes them) returns the same rows as a local run (identical counters, hits,
    parameters; times present), and a client without the certificate cannot connect. Run as its own
    script, as a user runs a sweep (worker processes are spawned from a clean main module)."""
    pytest.importorskip("dask.distributed")
    pytest.importorskip("cryptography")
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path
    script = tmp_path / "tls_sweep.py"
    script.write_text(_TLS_SWEEP)
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    p = subprocess.run([sys.executable, str(script), str(tmp_path)], capture_output=True, text=True, env=env,
                       timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    res = json.loads(p.stdout.strip().splitlines()[-1])
    assert res["address"].startswith("tls://") and res["refused"] == [True, True]
    assert len(res["local"]) == 6 and res["local"] == res["remote"] and all(res["remote_ok"])
