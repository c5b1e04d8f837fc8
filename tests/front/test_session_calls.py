"""session_calls.py's protocol check: client_protocol read from a serialized CreateSessionRequest
without parsing the scene, as protobuf would read it, and a client newer than the server refused
FAILED_PRECONDITION naming both protocols (the same words as gRPC's metadata check)."""

from __future__ import annotations

import grpc
import pytest

from camdirector.errors import DirectorError
from camdirector.front.grpc_service import check_protocol_metadata
from camdirector.front.session_calls import check_client_protocol, client_protocol_of
from camdirector.v1 import director_pb2 as pb
from camdirector.version import PROTOCOL, VERSION
from tests.service.wire_client import two_target_request

REFUSAL = (
    f"this client speaks camdirector protocol {PROTOCOL + 1}, this server (camdirector {VERSION}) "
    f"protocol {PROTOCOL}: upgrade the server, or use a client of release {VERSION}"
)


def _mesh_request(**fields) -> pb.CreateSessionRequest:
    """A scene with a triangle mesh (length-delimited fields, fixed-width floats) and every scalar."""
    request = two_target_request(seed=2**40, record=True, level_id="lvl", delay_s=1.5, **fields)
    request.objects.add(
        id="tri", mesh=pb.Mesh(triangles=pb.TriangleMesh(vertices=[0.0, 1.0, 2.5] * 300, indices=list(range(300))))
    )
    return request


@pytest.mark.parametrize("said", [0, PROTOCOL, PROTOCOL + 1, 300, 2**32 - 1])
def test_client_protocol_is_read_as_protobuf_reads_it(said):
    payload = _mesh_request(client_protocol=said).SerializeToString()
    assert client_protocol_of(payload) == pb.CreateSessionRequest.FromString(payload).client_protocol == said


def test_the_last_occurrence_counts_and_a_uint32_keeps_its_low_bits():
    twice = pb.CreateSessionRequest(client_protocol=7).SerializeToString() + _mesh_request(client_protocol=3).SerializeToString()
    assert client_protocol_of(twice) == pb.CreateSessionRequest.FromString(twice).client_protocol == 3
    wide = bytes([10 << 3]) + bytes([0x82, 0x80, 0x80, 0x80, 0x10])  # 2 + 2**32 as a varint
    assert client_protocol_of(wide) == pb.CreateSessionRequest.FromString(wide).client_protocol == 2


@pytest.mark.parametrize("payload", [b"", b"\xff\xff\xff", b"\x0a\x05ab", bytes([10 << 3]), b"\x00\x01"])
def test_absent_or_unreadable_is_not_said(payload):
    assert client_protocol_of(payload) == 0


def test_a_newer_client_is_refused_with_both_protocols():
    for said in (0, PROTOCOL):
        check_client_protocol(said)
    with pytest.raises(DirectorError) as refused:
        check_client_protocol(PROTOCOL + 1)
    assert refused.value.code == grpc.StatusCode.FAILED_PRECONDITION and refused.value.message == REFUSAL


def test_the_metadata_check_says_the_same():
    check_protocol_metadata(None)  # a client from before the header
    check_protocol_metadata(str(PROTOCOL))
    with pytest.raises(DirectorError) as refused:
        check_protocol_metadata(str(PROTOCOL + 1))
    assert refused.value.code == grpc.StatusCode.FAILED_PRECONDITION and refused.value.message == REFUSAL
    for bad in ("two", "²", "-1", ""):
        with pytest.raises(DirectorError) as err:
            check_protocol_metadata(bad)
        assert err.value.code == grpc.StatusCode.INVALID_ARGUMENT and "not a whole number" in err.value.message
