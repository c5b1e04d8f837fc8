"""The binary framing of the socket pair between the front and a worker (infra/channels.py):
requests and replies come out as they went in, over a real socket pair, whatever their size; a
create request carries its session's tenant. A monitor's view query and its answer cross as they
were, and a query out of range is refused."""

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
    ViewQuery,
    decode_create,
    decode_reply_tail,
    decode_view,
    encode_create,
    encode_reply,
    encode_request,
    encode_view,
    read_request,
    tail_length,
)
from camdirector.v1 import director_pb2 as pb


@pytest.mark.parametrize(
    "op, session_id, payload",
    [
        ("frame", "4296f374589b4d8987f2b500edea56b5", b"\x0a\x20" + bytes(range(200))),
        ("ping", "", b""),
        ("create", "ünï", bytes(3_000_000)),  # larger than the reader's buffer and the socket's
        ("drop", "s", b""),
    ],
)
def test_a_request_crosses_the_socket_pair_unchanged(op, session_id, payload):
    front, worker = socket.socketpair()
    request_id = REQUEST_ID_MODULUS - 1
    # a writer thread: a large request does not fit the socket's buffer before it is read
    writer = threading.Thread(target=lambda: [front.sendall(b) for b in encode_request(request_id, op, session_id, payload)])
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


@pytest.mark.parametrize(
    "metrics",
    [
        FrameMetrics(0.55, {"ingest": 0.02, "framing": 0.041, "motion": 0.13, "visibility": 0.185}, False),
        FrameMetrics(0.012, {}, True),  # a stale frame: no stage ran
        FrameMetrics(3.5, {"cut_check": 1.0, "target_update": 0.25, "camera_update": 2.0}, False),  # the tracks rig
        None,
    ],
)
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
    assert decode_create(request) == ("default", request)  # a checkpoint written before tenants


@pytest.mark.parametrize(
    "fields, message",
    [
        ({"shot": "sideways"}, "view shot must be one of"),
        ({"width_px": 5000}, "view width must be in [16, 1280] px"),
        ({"width_px": 8}, "view width must be in [16, 1280] px"),
        ({"height_px": 721}, "view height must be in [16, 720] px"),
        ({"image_format": "gif"}, "view format must be one of jpeg, png"),
        ({"shot": "candidate"}, "a candidate view names the candidate's players"),
    ],
)
def test_view_queries_out_of_range_are_refused(fields, message):
    with pytest.raises(ValueError) as refused:
        ViewQuery(**fields)
    assert message in str(refused.value)


def test_a_view_query_survives_its_trip_to_the_worker_and_garbage_is_refused():
    query = ViewQuery(shot="candidate", subjects=("p1", "p6"), width_px=640, height_px=200, image_format="png")
    assert ViewQuery.from_json(query.to_json()) == query
    for payload in (b"", b"[]", b'{"shot": "program"}', b"\xff"):
        with pytest.raises(ValueError, match="not a view query"):
            ViewQuery.from_json(payload)
    with pytest.raises(ValueError, match="view shot must be one of"):  # well formed, out of range: its own reason
        ViewQuery.from_json(ViewQuery().to_json().replace(b"program", b"sideways"))


def test_a_view_comes_back_as_its_header_and_image():
    header = {"frame": 12, "placeholder": None, "render_ms": 3.5, "media_type": "image/png", "bounds": [0.0, 1.0]}
    assert decode_view(encode_view(header, b"\x89PNG...")) == (header, b"\x89PNG...")
