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
message as its length arrived). The attacker's CPU is on the same machine, so a third run is the floor: the same attacker, at the
same pace, aimed at a sink in a process of its own that refuses everything it is sent the cheapest
way (reads an HTTP request's head, answers 401 and closes; a ZeroMQ socket with the server's size
limit and CURVE). `rtt_ratio_attacked_vs_sink` is the server's own share of the cost: 1 when the
frames see no more of the attack than of the machine it runs on.
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
from camdirector.front.zmq_service import ENVELOPE_SLACK_BYTES
from load_tests import stream
from load_tests.report import emit, percentiles

SERVER_LIMIT_BYTES = 4 * 1024 * 1024  # the server's max_message_bytes and max_upload_bytes
_PIECE_BYTES = 64 * 1024
ZMQ_WAIT_MS = 200
KINDS = ("http_login", "http_login_chunked", "http_upload_without_key", "zmq_without_key")


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


def _attack(http: str, zmq_address: str, server_key: str, oversize_bytes: int, pause_s: float, only, stop, ready, out) -> None:
    """The attacker, in a process of its own: one thread per kind of attack, each sending at least
    one, until `stop` is set; sets `ready` once every kind has sent its first; sends {kind: (Counter
    of outcomes, answer latencies in ms)} through `out`."""
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
    kinds = {kind: send for kind, send in kinds.items() if not only or kind in only}
    results = {kind: (Counter(), []) for kind in kinds}
    first_sent = threading.Barrier(len(kinds), action=ready.set)

    def loop(kind):
        outcomes, latencies_ms = results[kind]
        while True:
            outcome, seconds = kinds[kind]()
            outcomes[outcome] += 1
            latencies_ms.append(seconds * 1e3)
            if len(latencies_ms) == 1:
                first_sent.wait()
            if stop.wait(pause_s):
                break

    threads = [threading.Thread(target=loop, args=(kind,)) for kind in kinds]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    out.send({kind: (dict(outcomes), latencies) for kind, (outcomes, latencies) in results.items()})


def _sink(out) -> None:
    """The floor's target, in a process of its own until killed: an HTTP listener that reads a
    request's head, answers 401 and closes, and a ZeroMQ ROUTER with CURVE and the server's size
    limit; sends (http HOST:PORT, zmq address, its CURVE public key) through `out`."""
    listener = socket.create_server(("127.0.0.1", 0), backlog=64)
    public, secret = zmq.curve_keypair()
    router = zmq.Context.instance().socket(zmq.ROUTER)
    router.curve_server, router.curve_secretkey = True, secret
    router.setsockopt(zmq.MAXMSGSIZE, SERVER_LIMIT_BYTES + ENVELOPE_SLACK_BYTES)
    port = router.bind_to_random_port("tcp://127.0.0.1")
    out.send((f"127.0.0.1:{listener.getsockname()[1]}", f"tcp://127.0.0.1:{port}", public.decode()))

    def answer_zmq() -> None:  # nothing gets through the size limit; answered if it did
        while True:
            peer, *_ = router.recv_multipart()
            router.send_multipart([peer, b"3", b"refused"])

    threading.Thread(target=answer_zmq, daemon=True).start()
    while True:
        connection, _ = listener.accept()
        with connection:
            head = b""
            while b"\r\n\r\n" not in head and (piece := connection.recv(4096)):
                head += piece
            with contextlib.suppress(OSError):
                connection.sendall(b"HTTP/1.1 401 Unauthorized\r\nContent-Length: 0\r\nConnection: close\r\n\r\n")


@contextlib.contextmanager
def _sink_process():
    """Starts _sink; yields its (http, zmq, zmq public key) and kills it on leaving."""
    context = multiprocessing.get_context("spawn")
    receive, send = context.Pipe(duplex=False)
    process = context.Process(target=_sink, args=(send,), daemon=True)
    process.start()
    try:
        yield receive.recv()
    finally:
        process.kill()
        process.join()


@contextlib.asynccontextmanager
async def _attacker(target: tuple[str, str, str], oversize_bytes: int, pause_s: float, only: list[str], report: dict):
    """The attacker process aimed at `target` (http HOST:PORT, zmq address, zmq public key) while
    the context is entered; its outcomes land in `report`."""
    context = multiprocessing.get_context("spawn")
    stop, ready = context.Event(), context.Event()
    receive, send = context.Pipe(duplex=False)
    args = (*target, oversize_bytes, pause_s, only, stop, ready, send)
    process = context.Process(target=_attack, args=args, daemon=True)
    process.start()
    try:
        # the frames start once every kind of attack has sent one: a spawned process's start took
        # longer than a 1-s run on a busy machine, which then saw no attack
        if not await asyncio.to_thread(ready.wait, 60):
            raise RuntimeError("the attacker process did not start its attacks within 60 s")
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
    parser.add_argument("--only", action="append", default=[], choices=KINDS, help="this kind of attack only (repeatable)")
    parser.add_argument("--workers", type=int, default=None, help="server worker processes (default: cores)")
    parser.add_argument("--json", type=Path, help="also write the result here")
    args = parser.parse_args(argv)
    workers = args.workers if args.workers is not None else (os.cpu_count() or 1)
    oversize_bytes = int(args.oversize_mib * 1024 * 1024)
    limit = str(SERVER_LIMIT_BYTES)
    attacks: dict = {}
    floor_attacks: dict = {}

    def frames(alongside=None) -> dict:
        return asyncio.run(
            stream.run("grpc", server.grpc, args.sessions, args.rate, args.seconds, alongside=alongside, key=server.admin_key)
        )

    def attacking(target: tuple[str, str, str], report: dict):
        return lambda _: _attacker(target, oversize_bytes, args.pause_s, args.only, report)

    with ServerProcess("--workers", str(workers), "--max-message-bytes", limit, "--max-upload-bytes", limit, auth=True) as server:
        quiet = frames()
        with _sink_process() as sink:
            floor = frames(attacking(sink, floor_attacks))
        attacked = frames(attacking((server.http, server.zmq, server.zmq_server_key), attacks))
        alive = server.alive()

    def ratio(over: dict, under: dict) -> dict:
        return {k: over["rtt_ms"][k] / under["rtt_ms"][k] for k in ("p50", "p99", "max") if under["rtt_ms"][k]}

    result = {
        "sessions": args.sessions,
        "rate_hz": args.rate,
        "seconds": args.seconds,
        "oversize_bytes": oversize_bytes,
        "server_limit_bytes": SERVER_LIMIT_BYTES,
        "server_workers": workers,
        "quiet": _frames(quiet),
        "attacker_at_sink": _frames(floor),
        "attacked": _frames(attacked),
        "rtt_ratio_attacked_vs_quiet": ratio(attacked, quiet),
        "rtt_ratio_attacked_vs_sink": ratio(attacked, floor),
        "attacks": attacks,
        "attacks_at_sink": {kind: report["sent"] for kind, report in floor_attacks.items()},
        "cpus": os.cpu_count(),
    }
    emit(result, args.json)
    runs = (quiet, floor, attacked)
    ok = alive and all(a["sent"] for a in attacks.values()) and not any(run["errors"] or run["dropped_frames"] for run in runs)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
