"""The binary framing of the socket pair between the front and a worker (infra/channels.py):
requests and replies come out as they went in, over a real socket pair, whatever their size; a
create request carries its session's tenant."""
from __future__ import annotations

import asyncio
import socket
import threading

import pytest

from camdirector.infra.channels import (
    OPS,
    REPLY,
    REQUEST,
    REQUEST_ID_MODULUS,
    FrameMetrics,
    decode_create,
    decode_reply_tail,
    encode_create,
    encode_reply,
    encode_request,
    read_request,
    tail_length,
)
from camdirector.v1 import director_pb2 as pb


@pytest.mark.parametrize("op, session_id, payload", [
    ("frame", "4296f374589b4d8987f2b500edea56b5", b"\x0a\x20" + bytes(range(200))),
    ("ping", "", b""),
    ("create", "ünï", bytes(3_000_000)),  # larger than the reader's buffer and the socket's
    ("drop", "s", b""),
])
def test_a_request_crosses_the_socket_pair_unchanged(op, session_id, payload):
    front, worker = socket.socketpair()
    request_id = REQUEST_ID_MODULUS - 1
    # a writer thread: a large request does not fit the socket's buffer before it is read
    writer = threading.Thread(target=lambda: [front.sendall(b) for b in encode_request(request_id, op, session_id,
                                                                                          payload)])
    writer.start()
    with worker.makefile("rb", buffering=1 << 16) as reader:
        assert read_request(reader) == (request_id, op, session_id, payload)
        writer.join()
        front.close()
        with pytest.raises(EOFError):  # the front went away
            read_request(reader)
    worker.close()


def test_every_op_has_a_code():
    assert len(set(OPS)) == len(OPS) < 256
    for op in OPS:
        assert encode_request(1, op, "s", b"")[0][4] == OPS.index(op)


async def _read_reply(data: bytes):
    reader = asyncio.StreamReader()
    reader.feed_data(data)
    reader.feed_eof()
    header = REPLY.unpack(await reader.readexactly(REPLY.size))
    body, metrics = decode_reply_tail(header, await reader.readexactly(tail_length(header)))
    assert await reader.read() == b""  # nothing left over: the next reply starts where this one ends
    return header[0], header[1], body, metrics


@pytest.mark.parametrize("metrics", [
    FrameMetrics(0.55, {"ingest": 0.02, "framing": 0.041, "motion": 0.13, "visibility": 0.185}, False),
    FrameMetrics(0.012, {}, True),  # a stale frame: no stage ran
    FrameMetrics(3.5, {"cut_check": 1.0, "target_update": 0.25, "camera_update": 2.0}, False),  # the tracks rig
    None,
])
def test_a_reply_and_its_metrics_come_back_as_sent(metrics):
    body = b"\x08\x07" + bytes(300)
    request_id, status, got_body, got_metrics = asyncio.run(_read_reply(encode_reply(42, 0, body, metrics)))
    assert (request_id, status, got_body) == (42, 0, body)
    assert got_metrics == metrics  # float64 on the wire: the times are exact


def test_an_error_reply_carries_its_status_and_message():
    message = "unknown session id 'x' (closed, reclaimed, or never created)"
    request_id, status, body, metrics = asyncio.run(_read_reply(encode_reply(7, 5, message.encode(), None)))
    assert (request_id, status, body.decode(), metrics) == (7, 5, message, None)


class _Sized:
    """Stands for a payload of `n` bytes without holding them: the header only needs its length."""

    def __init__(self, n: int):
        self.n = n

    def __len__(self) -> int:
        return self.n


def test_a_multi_gib_payload_length_survives_the_header():
    # multiprocessing's framing needed an escape past 2 GiB; the REQUEST header holds 64 bits
    header = encode_request(3, "create", "s", _Sized(5 << 30))[0]
    assert REQUEST.unpack(header) == (3, OPS.index("create"), 1, 5 << 30)


def test_a_create_payload_carries_the_tenant_and_reads_one_from_before_tenants():
    request = pb.CreateSessionRequest(level_id="arena", seed=7).SerializeToString()
    tenant, body = decode_create(encode_create("a" * 63, request))
    assert tenant == "a" * 63 and bytes(body) == request
    assert pb.CreateSessionRequest.FromString(body).level_id == "arena"
    assert decode_create(encode_create("acme", b"")) == ("acme", b"")
    assert decode_create(request) == ("default", request)   # a checkpoint written before tenants
