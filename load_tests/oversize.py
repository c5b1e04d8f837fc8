"""Oversize requests from callers without a key: what they cost the frames of the sessions that stream.

    python -m load_tests.oversize --sessions 4 --rate 60 --seconds 10 --oversize-mib 12 --json FILE

One server with keys (`--max-message-bytes` and `--max-upload-bytes` at 4 MiB) and two runs of
`load_tests.stream` against it (demo scene, paced game loops over gRPC, the admin key): first the
sessions alone, the baseline, then the same again while an attacker in a process of its own sends,
as fast as it is answered with `--pause-s` between, each of: a `--oversize-mib` JSON body to
`POST /v1/login` (Content-Length), the same chunked, an upload to `POST /v1/levels` without a key
(of the server's upload limit: within it, so that the key is what refuses it) and a ZeroMQ
CreateSession of `--oversize-mib` without a key (CURVE with the server's public key, which is no
secret). The HTTP attacker sends its whole body unless the server answers first. Reports both
runs' frame round trips (p50/p99/max, ms) and their ratio, and per kind of attack how many were
sent, how they were answered and how long the answer took: the HTTP status, or "closed" when the
server closed the connection (its answer sent, the rest of the body unread) before the attacker
read the answer; for ZeroMQ "dropped" when no answer came within ZMQ_WAIT_MS (libzmq refused the
message as its length arrived). The attacker's CPU is on the same machine, so the ratio includes it as well as the
server's.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import multiprocessing
import os
import select
import socket
import sys
import threading
import time
from collections import Counter
from pathlib import Path

import zmq

from camdirector.deploy.server_process import ServerProcess
from load_tests import stream
from load_tests.report import emit, percentiles

SERVER_LIMIT_BYTES = 4 * 1024 * 1024  # the server's max_message_bytes and max_upload_bytes
_PIECE_BYTES = 64 * 1024
ZMQ_WAIT_MS = 200


def _http_attack(http: str, head: bytes, body_bytes: int, chunked: bool) -> tuple[str, float]:
    """Sends one request of `body_bytes`, piece by piece, stopping when the server answers;
    returns (its status, or "closed"/"timeout", seconds until the answer)."""
    host, port = http.rsplit(":", 1)
    t0 = time.perf_counter()
    with socket.create_connection((host, int(port)), timeout=30) as sock:
        sock.sendall(head + b"\r\n")
        piece = b"x" * _PIECE_BYTES
        sent = 0
        try:
            while sent < body_bytes and not select.select([sock], [], [], 0)[0]:
                sock.sendall(b"%x\r\n%s\r\n" % (len(piece), piece) if chunked else piece)
                sent += len(piece)
            if chunked and sent >= body_bytes:
                sock.sendall(b"0\r\n\r\n")
            answer = sock.recv(4096)
        except OSError:  # the server closed while the body was still going
            answer = b""
    status = answer.split(b" ", 2)[1].decode() if answer.startswith(b"HTTP/") else "closed"
    return status, time.perf_counter() - t0


def _zmq_attack(address: str, server_key: str, payload: bytes) -> tuple[str, float]:
    ctx = zmq.Context.instance()
    sock = ctx.socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.curve_serverkey = server_key.encode()
    sock.curve_publickey, sock.curve_secretkey = zmq.curve_keypair()
    sock.connect(address)
    t0 = time.perf_counter()
    sock.send_multipart([b"CreateSession", payload])
    answered = sock.poll(ZMQ_WAIT_MS)
    outcome = sock.recv_multipart()[0].decode() if answered else "dropped"
    sock.close()
    return f"code {outcome}" if answered else outcome, time.perf_counter() - t0


def _attack(http: str, zmq_address: str, server_key: str, oversize_bytes: int, pause_s: float, stop, out) -> None:
    """The attacker, in a process of its own: one thread per kind of attack until `stop` is set;
    sends {kind: (Counter of outcomes, answer latencies in ms)} through `out`."""
    login = b"POST /v1/login HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
    upload = b"POST /v1/levels HTTP/1.1\r\nHost: x\r\nContent-Type: multipart/form-data; boundary=b\r\n"
    length = b"Content-Length: %d\r\n" % oversize_bytes
    kinds = {
        "http_login": lambda: _http_attack(http, login + length, oversize_bytes, chunked=False),
        "http_login_chunked": lambda: _http_attack(http, login + b"Transfer-Encoding: chunked\r\n", oversize_bytes, chunked=True),
        "http_upload_without_key": lambda: _http_attack(
            http, upload + b"Content-Length: %d\r\n" % SERVER_LIMIT_BYTES, SERVER_LIMIT_BYTES, chunked=False
        ),
        "zmq_without_key": lambda: _zmq_attack(zmq_address, server_key, b"\x00" * oversize_bytes),
    }
    results = {kind: (Counter(), []) for kind in kinds}

    def loop(kind):
        outcomes, latencies_ms = results[kind]
        while not stop.is_set():
            outcome, seconds = kinds[kind]()
            outcomes[outcome] += 1
            latencies_ms.append(seconds * 1e3)
            stop.wait(pause_s)

    threads = [threading.Thread(target=loop, args=(kind,)) for kind in kinds]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    out.send({kind: (dict(outcomes), latencies) for kind, (outcomes, latencies) in results.items()})


@contextlib.asynccontextmanager
async def _attacker(server: ServerProcess, oversize_bytes: int, pause_s: float, report: dict):
    context = multiprocessing.get_context("spawn")
    stop = context.Event()
    receive, send = context.Pipe(duplex=False)
    args = (server.http, server.zmq, server.zmq_server_key, oversize_bytes, pause_s, stop, send)
    process = context.Process(target=_attack, args=args, daemon=True)
    process.start()
    try:
        yield
    finally:
        stop.set()
        attacks = await asyncio.to_thread(receive.recv)
        process.join(30)
        report.update(
            {
                kind: {"sent": sum(outcomes.values()), "outcomes": outcomes, "answer_ms": percentiles(latencies)}
                for kind, (outcomes, latencies) in attacks.items()
            }
        )


def _frames(run: dict) -> dict:
    return {k: run[k] for k in ("rtt_ms", "compute_ms", "late_frames", "dropped_frames", "errors")}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=4)
    parser.add_argument("--rate", type=float, default=60.0, help="frames per second per session")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--oversize-mib", type=float, default=12.0, help="size of each attack's body or message, MiB")
    parser.add_argument("--pause-s", type=float, default=0.05, help="each attacker's pause between two requests, s")
    parser.add_argument("--workers", type=int, default=None, help="server worker processes (default: cores)")
    parser.add_argument("--json", type=Path, help="also write the result here")
    args = parser.parse_args(argv)
    workers = args.workers if args.workers is not None else (os.cpu_count() or 1)
    oversize_bytes = int(args.oversize_mib * 1024 * 1024)
    limit = str(SERVER_LIMIT_BYTES)
    attacks: dict = {}
    with ServerProcess("--workers", str(workers), "--max-message-bytes", limit, "--max-upload-bytes", limit, auth=True) as server:
        quiet = asyncio.run(stream.run("grpc", server.grpc, args.sessions, args.rate, args.seconds, key=server.admin_key))
        attacked = asyncio.run(
            stream.run(
                "grpc",
                server.grpc,
                args.sessions,
                args.rate,
                args.seconds,
                alongside=lambda _: _attacker(server, oversize_bytes, args.pause_s, attacks),
                key=server.admin_key,
            )
        )
        alive = server.alive()
    ratio = {k: attacked["rtt_ms"][k] / quiet["rtt_ms"][k] for k in ("p50", "p99", "max") if quiet["rtt_ms"][k]}
    result = {
        "sessions": args.sessions,
        "rate_hz": args.rate,
        "seconds": args.seconds,
        "oversize_bytes": oversize_bytes,
        "server_limit_bytes": SERVER_LIMIT_BYTES,
        "server_workers": workers,
        "quiet": _frames(quiet),
        "attacked": _frames(attacked),
        "rtt_ratio_attacked_vs_quiet": ratio,
        "attacks": attacks,
        "cpus": os.cpu_count(),
    }
    emit(result, args.json)
    ok = alive and not quiet["errors"] and not attacked["errors"] and all(a["sent"] for a in attacks.values())
    return 0 if ok and quiet["dropped_frames"] == attacked["dropped_frames"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
