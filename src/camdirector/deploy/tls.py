"""A certificate authority and a server certificate it signed, made with the openssl command
(Debian's, installed with the system packages): what a studio's own CA gives, for the servers
that this project starts itself. The cluster on one machine (deploy/cluster.py) makes one set in
its folder: the balancer and every node present the certificate, clients and HAProxy trust the CA.
The TLS tests make theirs through the `tls_files` fixture. For docker/compose.cluster.yaml:

    python -m camdirector.deploy.tls docker/tls

The private keys are readable by their owner alone (mode 0600), and the CA's is deleted once it
has signed: nothing else can be made that the CA's certificate vouches for.
"""

from __future__ import annotations

import argparse
import os
import subprocess
from dataclasses import dataclass
from pathlib import Path

HOSTS = ("127.0.0.1", "localhost")  # what a loopback server's certificate names (its subjectAltName)


@dataclass(frozen=True)
class TlsFiles:
    ca_cert: Path  # the CA's certificate: what clients trust (`ca_file`)
    cert: Path  # the server's certificate, signed by the CA (`--tls-cert`)
    key: Path  # its private key (`--tls-key`)
    bundle: Path  # the certificate and its key in one file, as HAProxy's `crt` reads them


def _openssl(*args: str) -> None:
    subprocess.run(["openssl", *args], check=True, capture_output=True)


def files_in(folder: Path) -> TlsFiles:
    """The files `make_tls_files` makes in `folder` (where a container mounts them, too)."""
    return TlsFiles(folder / "ca.pem", folder / "server.pem", folder / "server.key", folder / "bundle.pem")


def make_tls_files(folder: Path, hosts: tuple[str, ...] = HOSTS, days: int = 365) -> TlsFiles:
    """A CA and a certificate for `hosts` (IP addresses and names: its subjectAltName), valid for
    `days`, in `folder`; what was needed only to sign is removed."""
    folder.mkdir(parents=True, exist_ok=True)
    made = files_in(folder)
    ca_key, ca_cert, key, cert = folder / "ca.key", made.ca_cert, made.key, made.cert
    csr, ext = folder / "server.csr", folder / "server.ext"
    _openssl(
        "req",
        "-x509",
        "-newkey",
        "ec",
        "-pkeyopt",
        "ec_paramgen_curve:prime256v1",
        "-nodes",
        "-keyout",
        str(ca_key),
        "-out",
        str(ca_cert),
        "-days",
        str(days),
        "-subj",
        "/CN=camdirector CA",
        "-addext",
        "basicConstraints=critical,CA:TRUE",
        "-addext",
        "keyUsage=critical,keyCertSign,cRLSign",
    )
    _openssl(
        "req",
        "-newkey",
        "ec",
        "-pkeyopt",
        "ec_paramgen_curve:prime256v1",
        "-nodes",
        "-keyout",
        str(key),
        "-out",
        str(csr),
        "-subj",
        f"/CN={hosts[0]}",
    )
    san = ",".join(f"IP:{h}" if h.replace(".", "").isdigit() or ":" in h else f"DNS:{h}" for h in hosts)
    ext.write_text(f"subjectAltName={san}\nbasicConstraints=CA:FALSE\nkeyUsage=digitalSignature\nextendedKeyUsage=serverAuth\n")
    _openssl(
        "x509",
        "-req",
        "-in",
        str(csr),
        "-CA",
        str(ca_cert),
        "-CAkey",
        str(ca_key),
        "-CAcreateserial",
        "-out",
        str(cert),
        "-days",
        str(days),
        "-extfile",
        str(ext),
    )
    for used in (ca_key, csr, ext, folder / "ca.srl"):
        used.unlink()
    key.chmod(0o600)
    fd = os.open(made.bundle, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)  # never readable by others, not even briefly
    with os.fdopen(fd, "wb") as f:
        f.write(cert.read_bytes() + key.read_bytes())
    return made


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=f"make a CA and a certificate for {', '.join(HOSTS)} signed by it")
    parser.add_argument("folder", type=Path)
    made = make_tls_files(parser.parse_args().folder)
    print(f"CA {made.ca_cert}, certificate {made.cert}, key {made.key}, HAProxy's bundle {made.bundle}")
