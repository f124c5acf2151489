"""TLS for a distributed sweep: a cluster only its owner can use.

A Dask worker runs whatever a client submits, so a scheduler reachable on plain ``tcp://`` lets
anyone who reaches its port run code on every worker. gridcost's recipe is mutual TLS
(`Dask's TLS docs <https://distributed.dask.org/en/stable/tls.html>`_): one private CA made by
``gridcost certs``, one certificate signed by it that the scheduler, the workers and the client all
present (``distributed.Security`` with ``require_encryption=True``). Whoever lacks the CA-signed key
cannot connect. The files are written 0600 (the CA key never leaves the owner's machine: workers
need only ``ca.pem``, ``node.pem`` and ``node-key.pem``).
"""
from __future__ import annotations

import datetime
import ipaddress
import socket
from pathlib import Path
from urllib.parse import urlparse

from tracer.errors import GridcostError
from tracer.storage import atomic_write

#: file names inside a certificate folder
CA, CA_KEY, CERT, KEY = "ca.pem", "ca-key.pem", "node.pem", "node-key.pem"
#: validity of the certificates ``gridcost certs`` makes (a sweep's lifetime, not a server's)
DAYS = 30


def make_certs(folder, hosts=()) -> dict:
    """A CA and one node certificate signed by it (names: localhost, 127.0.0.1, this host's name and
    ``hosts``), written into ``folder``. Returns {kind: path}."""
    try:
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes, serialization
        from cryptography.hazmat.primitives.asymmetric import ec
        from cryptography.x509.oid import NameOID
    except ImportError:
        raise GridcostError("making certificates needs the 'cryptography' package: pip install 'gridcost[dask]'") from None
    folder = Path(folder)
    now = datetime.datetime.now(datetime.timezone.utc)
    until = now + datetime.timedelta(days=DAYS)

    def name(cn):
        return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, cn)])

    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca = (x509.CertificateBuilder().subject_name(name("gridcost sweep CA")).issuer_name(name("gridcost sweep CA"))
          .public_key(ca_key.public_key()).serial_number(x509.random_serial_number())
          .not_valid_before(now).not_valid_after(until)
          .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
          .sign(ca_key, hashes.SHA256()))
    sans = []
    for h in dict.fromkeys(["localhost", "127.0.0.1", socket.gethostname(), *hosts]):
        try:
            sans.append(x509.IPAddress(ipaddress.ip_address(h)))
        except ValueError:
            sans.append(x509.DNSName(h))
    key = ec.generate_private_key(ec.SECP256R1())
    cert = (x509.CertificateBuilder().subject_name(name("gridcost node")).issuer_name(ca.subject)
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now).not_valid_after(until)
            .add_extension(x509.SubjectAlternativeName(sans), critical=False)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .sign(ca_key, hashes.SHA256()))

    def pem_key(k):
        return k.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                               serialization.NoEncryption())
    files = {"ca": (CA, ca.public_bytes(serialization.Encoding.PEM)), "ca_key": (CA_KEY, pem_key(ca_key)),
             "cert": (CERT, cert.public_bytes(serialization.Encoding.PEM)), "key": (KEY, pem_key(key))}
    return {k: atomic_write(folder / fn, data, mode=0o600) for k, (fn, data) in files.items()}


def security(folder):
    """``distributed.Security`` for the client (and a local cluster) from a certificate folder."""
    from distributed import Security
    folder = Path(folder)
    missing = [f for f in (CA, CERT, KEY) if not (folder / f).is_file()]
    if missing:
        raise GridcostError(f"{folder}: no {', '.join(missing)} (make them with `gridcost certs --dir {folder}`)")
    ca, cert, key = (str(folder / f) for f in (CA, CERT, KEY))
    return Security(tls_ca_file=ca, tls_client_cert=cert, tls_client_key=key, tls_scheduler_cert=cert,
                    tls_scheduler_key=key, tls_worker_cert=cert, tls_worker_key=key, require_encryption=True)


def check_address(address: str, tls_dir, insecure: bool) -> None:
    """Refuse a plain ``tcp://`` scheduler beyond loopback unless ``--insecure``; ``tls://`` needs
    ``--tls``."""
    url = urlparse(address if "://" in address else f"tcp://{address}")
    if url.scheme == "tls":
        if tls_dir is None:
            raise GridcostError(f"{address}: a tls:// scheduler needs --tls DIR (the folder `gridcost certs` made)")
        return
    if url.scheme != "tcp":
        raise GridcostError(f"{address}: unknown scheduler protocol {url.scheme!r} (tls://HOST:PORT, or tcp:// on "
                            "loopback)")
    host = url.hostname or ""
    try:
        loopback = host == "localhost" or ipaddress.ip_address(host).is_loopback
    except ValueError:
        loopback = False
    if not loopback and not insecure:
        raise GridcostError(f"{address}: plain tcp:// beyond this machine lets anyone who reaches the port run code "
                            "on every worker; use tls:// with --tls DIR (gridcost certs), or --insecure on a network "
                            "you trust")
