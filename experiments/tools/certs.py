"""``certs``: the certificates of a distributed sweep only its owner can use (mutual TLS,
:mod:`experiments.core.tls`).

    gridcost certs --dir ~/.gridcost-tls --hosts node1,node2
"""
from __future__ import annotations

from pathlib import Path

from experiments.core.tls import CA_KEY, make_certs


def add_arguments(p) -> None:
    p.add_argument("--dir", required=True, help="folder to write ca.pem, ca-key.pem, node.pem, node-key.pem into")
    p.add_argument("--hosts", default="", help="comma-separated host names or IPs of the scheduler and workers")


def main(ctx, args) -> int:
    hosts = [h.strip() for h in args.hosts.split(",") if h.strip()]
    paths = make_certs(Path(args.dir).expanduser(), hosts)
    d = Path(args.dir).expanduser()
    print(f"wrote {', '.join(p.name for p in paths.values())} into {d} (mode 0600; copy all but {CA_KEY} to each "
          "worker machine)\n"
          f"  dask scheduler --protocol tls --port 8786 --tls-ca-file {d}/ca.pem --tls-cert {d}/node.pem "
          f"--tls-key {d}/node-key.pem\n"
          f"  dask worker tls://HOST:8786 --nthreads 1 --tls-ca-file {d}/ca.pem --tls-cert {d}/node.pem "
          f"--tls-key {d}/node-key.pem\n"
          f"  gridcost table2 --threads 1 --dask tls://HOST:8786 --tls {d}")
    return 0
