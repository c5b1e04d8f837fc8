"""camdirector._native's frame wire (native/src/wire.rs) against the Python codec
(worker/codec.py), the reference.

Decode: `frame_from_wire` (the request's bytes read and checked in Rust) gives every FrameUpdate
the FrameInput that `frame_from_msg` gives its parse: the same session, frame, time, ids,
positions and scales to the bit, rotations divided by norms at most one ulp apart (the norm is
summed in order in Rust, which gives numpy's bits for packed states; a state's norm is numpy's dot,
by its BLAS, up to 3 ulps off in a component). It refuses every bad frame with the same status and message, also
where a frame is bad in several ways (the first check that fails, in frame_from_msg's order). The
same holds for bytes that merge fields given twice, carry packed_transforms unpacked, or hold
unknown fields or known fields of another wire type. A frame with game events or player stats
goes through frame_from_msg.

Encode: `camera_update_wire` writes the bytes of `camera_update_msg(...).SerializeToString()` for
any state without a MATCH part. upb writes a map's entries in the order of its hash table, which
is seeded per process, so these tests compare with `SerializeToString(deterministic=True)`. Where
a key is a proper prefix of another, upb's deterministic order puts the longer key first and the
wire's does not; there the parsed messages are compared."""

from __future__ import annotations

import math
import struct

import grpc
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from camdirector import _native as native
from camdirector.demo.client import frame_updates
from camdirector.demo.scene import build_demo_scene
from camdirector.errors import DirectorError
from camdirector.geometry.camera import CameraPose
from camdirector.geometry.toric import make_torus
from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.inputs import FrameInput
from camdirector.pipeline.match.frame import MatchFrame
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.toric.frame import ToricFrame
from camdirector.v1 import director_pb2 as pb
from camdirector.worker import codec

# Quaternions past 1e154 overflow numpy's norm in the Python codec (both sides then take them as zero rotations)
pytestmark = pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
FAST = settings(max_examples=300, derandomize=True, deadline=None, database=None)

# The session's ids, with the characters repr() escapes or quotes differently
MOVABLE = {"avatar", "box-1", "o'q", 'd"q', "both'\"", "é", "tab\tid", "bell\x07", "🎥", "nl\nid"}
STATIC = {"wall", "st'atic", "\u200bzero-width"}
UNKNOWN = ["ghost", "", "x\x00y", "AVATAR"]
PLAYERS = frozenset({"avatar", "box-1"})
NAN, INF = math.nan, math.inf
EPS = float(np.finfo(np.float64).eps)

# doubles whose checks differ: finite, zero, tiny (under both limits), NaN, infinite
awkward = st.one_of(
    st.floats(width=64),
    st.sampled_from([0.0, -0.0, NAN, -NAN, INF, -INF, 1e-10, -5e-7, 1e-300, 5e-324, 1e200]),
)
finite = st.floats(allow_nan=False, allow_infinity=False)
coordinate = st.one_of(st.floats(-1e4, 1e4), finite)
quaternion = st.one_of(
    st.tuples(*[st.floats(-2.0, 2.0)] * 4),
    st.tuples(*[finite] * 4),
    st.sampled_from([(0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0, -1.0), (1e-3, 0.0, 0.0, 0.0)]),
).filter(lambda q: math.hypot(*q) > 1e-5)  # away from the 1e-6 limit, where an ulp of the norm decides
scale = st.one_of(st.floats(1e-8, 1e6), st.floats(-1e6, -1e-8), finite.filter(lambda x: abs(x) > 1e-8))


def vec3(values) -> pb.Vec3:
    return pb.Vec3(x=values[0], y=values[1], z=values[2])


@st.composite
def transforms(draw, good: bool) -> pb.Transform:
    """A Transform with each part set or not; `good`: one frame_from_msg takes."""
    out = pb.Transform()
    number = coordinate if good else awkward
    if draw(st.booleans()):
        out.position.CopyFrom(vec3(draw(st.tuples(number, number, number))))
    if draw(st.booleans()):
        x, y, z, w = draw(quaternion if good else st.tuples(awkward, awkward, awkward, awkward))
        out.rotation.CopyFrom(pb.Quat(x=x, y=y, z=z, w=w))
    if draw(st.booleans()):
        out.scale.CopyFrom(vec3(draw(st.tuples(*[scale if good else awkward] * 3))))
    return out


@st.composite
def packed_row(draw, good: bool) -> list[float]:
    if good:
        return [*draw(st.tuples(*[coordinate] * 3)), *draw(quaternion), *draw(st.tuples(*[scale] * 3))]
    return draw(st.lists(st.one_of(finite, awkward), min_size=10, max_size=10))


@st.composite
def frames(draw, good: bool) -> pb.FrameUpdate:
    """A FrameUpdate of states and packed states; `good`: one frame_from_msg takes, else one with
    any of its faults (unknown and static ids, bad numbers, a packed size off by a few)."""
    ids = st.sampled_from(sorted(MOVABLE) if good else [*sorted(MOVABLE), *sorted(STATIC), *UNKNOWN])
    states = draw(st.lists(st.tuples(ids, transforms(good)), max_size=4))
    packed_ids = draw(st.lists(ids, max_size=4))
    packed = [x for _ in packed_ids for x in draw(packed_row(good))]
    if not good and draw(st.integers(0, 4)) == 0:
        packed = packed[: draw(st.integers(0, len(packed)))] + draw(st.lists(finite, max_size=3))
    return pb.FrameUpdate(
        session_id=draw(st.text(max_size=12)),
        frame=draw(st.integers(0, 2**64 - 1)),
        time_s=draw(finite if good else st.one_of(finite, awkward)),
        states=[pb.ObjectState(id=i, transform=t) for i, t in states],
        packed_ids=packed_ids,
        packed_transforms=packed,
    )


def outcome(decode, *args) -> FrameInput | tuple[grpc.StatusCode, str]:
    """The decoded frame, or the (status, message) it was refused with."""
    try:
        return decode(*args)
    except DirectorError as exc:
        return exc.code, exc.message


def python(payload: bytes, player_ids: frozenset[str] | None = None):
    return outcome(codec.frame_from_msg, pb.FrameUpdate.FromString(payload), MOVABLE, STATIC, player_ids)


def wire(payload: bytes, player_ids: frozenset[str] | None = None):
    return outcome(codec.frame_from_wire, payload, pb.FrameUpdate.FromString(payload), MOVABLE, STATIC, player_ids)


def ulps(a: np.ndarray, b: np.ndarray) -> int:
    """The largest distance in units in the last place between a's and b's elements."""

    def ordered(x: np.ndarray) -> np.ndarray:
        bits = np.ascontiguousarray(x, dtype=np.float64).view(np.int64).astype(object)
        return np.array([v if v >= 0 else -(2**63) - v for v in bits], dtype=object)

    return int(max(abs(d) for d in ordered(a) - ordered(b))) if len(a) else 0


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return np.array_equal(np.ascontiguousarray(a).view(np.uint64), np.ascontiguousarray(b).view(np.uint64))


def assert_same(got, want) -> int:
    """got is want: the same refusal, or the same frame (rotations as divided by norms one ulp
    apart); the largest rotation difference in ulps."""
    if not isinstance(want, FrameInput):
        assert got == want
        return 0
    assert isinstance(got, FrameInput), got
    assert (got.session_id, got.frame, got.time_s) == (want.session_id, want.frame, want.time_s)
    assert type(got.frame) is int and type(got.time_s) is float
    assert (got.events, got.player_stats) == (want.events, want.player_stats)
    assert [i for i, _ in got.states] == [i for i, _ in want.states]
    if got.packed is not None:  # the rows the compiled rig moves its Scene by: the transforms' own values
        ids, rows = got.packed
        assert ids == [i for i, _ in got.states] and rows.shape == (len(ids), 10)
        made = [np.concatenate([t.position_world, t.rotation_xyzw, t.scale]) for _, t in got.states]
        assert all(same_bits(row, values) for row, values in zip(rows, made))
    worst = 0
    for (_, g), (_, w) in zip(got.states, want.states):
        assert same_bits(g.position_world, w.position_world) and same_bits(g.scale, w.scale)
        assert g.rotation_xyzw.shape == (4,) and g.position_world.shape == g.scale.shape == (3,)
        # one ulp of the norm, then the quotient's rounding: at most 2 eps of each component
        assert np.all(np.abs(g.rotation_xyzw - w.rotation_xyzw) <= 2 * EPS * np.abs(w.rotation_xyzw))
        worst = max(worst, ulps(g.rotation_xyzw, w.rotation_xyzw))
    return worst


@FAST
@given(frames(good=True))
def test_a_good_frame_decodes_as_the_python_codec_decodes_it(msg):
    payload = msg.SerializeToString()
    want = python(payload)
    assert isinstance(want, FrameInput)
    assert_same(wire(payload), want)


@FAST
@given(frames(good=False))
def test_any_frame_is_refused_as_the_python_codec_refuses_it(msg):
    payload = msg.SerializeToString()
    assert_same(wire(payload), python(payload))


def test_the_demo_frames_decode_alike():
    scene = build_demo_scene(seed=7, duration_s=11.0)
    movable = {scene.avatar.id, *(o.id for o in scene.dynamic_objects)}
    worst = 0
    for msg in frame_updates(scene, 600):
        msg.session_id = "s"
        want = codec.frame_from_msg(msg, movable, set())
        worst = max(worst, assert_same(codec.frame_from_wire(msg.SerializeToString(), msg, movable, set()), want))
    print({"rotation_ulps": worst})  # pytest -s


def state(object_id: str, **transform) -> pb.ObjectState:
    return pb.ObjectState(id=object_id, transform=pb.Transform(**transform))


GOOD_ROW = [1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 2.0, 1.0, 1.0, 1.0]
# Each refusal frame_from_msg makes, and the first of several faults
REFUSALS = {
    "time NaN": (pb.FrameUpdate(time_s=NAN, states=[state("ghost")]), grpc.StatusCode.INVALID_ARGUMENT),
    "unknown id": (pb.FrameUpdate(frame=7, states=[state("ghost")]), grpc.StatusCode.NOT_FOUND),
    "empty id": (pb.FrameUpdate(states=[state("")]), grpc.StatusCode.NOT_FOUND),
    "static id": (pb.FrameUpdate(states=[state("st'atic")]), grpc.StatusCode.FAILED_PRECONDITION),
    "position": (pb.FrameUpdate(states=[state("o'q", position=pb.Vec3(y=NAN))]), grpc.StatusCode.INVALID_ARGUMENT),
    "rotation": (pb.FrameUpdate(states=[state("bell\x07", rotation=pb.Quat(w=-INF))]), grpc.StatusCode.INVALID_ARGUMENT),
    "zero quaternion": (pb.FrameUpdate(states=[state("avatar", rotation=pb.Quat(x=1e-7))]), grpc.StatusCode.INVALID_ARGUMENT),
    "scale": (pb.FrameUpdate(states=[state("é", scale=pb.Vec3(x=1, y=1, z=INF))]), grpc.StatusCode.INVALID_ARGUMENT),
    "zero scale": (pb.FrameUpdate(states=[state("é", scale=pb.Vec3(x=1, y=1))]), grpc.StatusCode.INVALID_ARGUMENT),
    "the first state first": (
        pb.FrameUpdate(states=[state("avatar", scale=pb.Vec3()), state("ghost")]),
        grpc.StatusCode.INVALID_ARGUMENT,
    ),
    "states before packed": (
        pb.FrameUpdate(states=[state("wall")], packed_ids=["ghost"], packed_transforms=[NAN]),
        grpc.StatusCode.FAILED_PRECONDITION,
    ),
    "packed size": (pb.FrameUpdate(packed_ids=["ghost"], packed_transforms=GOOD_ROW[:9]), grpc.StatusCode.INVALID_ARGUMENT),
    "packed values without ids": (pb.FrameUpdate(packed_transforms=[1.0]), grpc.StatusCode.INVALID_ARGUMENT),
    "packed ids without values": (pb.FrameUpdate(packed_ids=["avatar"]), grpc.StatusCode.INVALID_ARGUMENT),
    "packed unknown id after a bad row": (
        pb.FrameUpdate(packed_ids=["avatar", "ghost"], packed_transforms=[NAN] * 10 + GOOD_ROW),
        grpc.StatusCode.NOT_FOUND,
    ),
    "packed static id": (
        pb.FrameUpdate(packed_ids=["avatar", "wall"], packed_transforms=GOOD_ROW * 2),
        grpc.StatusCode.FAILED_PRECONDITION,
    ),
    "packed NaN after a zero quaternion": (
        pb.FrameUpdate(packed_ids=["avatar", 'd"q'], packed_transforms=[0.0] * 10 + GOOD_ROW[:9] + [NAN]),
        grpc.StatusCode.INVALID_ARGUMENT,
    ),
    "packed zero quaternion after a zero scale": (
        pb.FrameUpdate(packed_ids=["avatar", "🎥"], packed_transforms=GOOD_ROW[:9] + [0.0] + [1.0] * 3 + [0.0] * 7),
        grpc.StatusCode.INVALID_ARGUMENT,
    ),
    "packed zero scale": (
        pb.FrameUpdate(packed_ids=["avatar", "nl\nid"], packed_transforms=GOOD_ROW + GOOD_ROW[:8] + [-1e-10, 1.0]),
        grpc.StatusCode.INVALID_ARGUMENT,
    ),
    "a bad state before events": (
        pb.FrameUpdate(states=[state("ghost")], events=[pb.GameEvent(kind=pb.EVENT_KILL)]),
        grpc.StatusCode.NOT_FOUND,
    ),
    "events in a session without players": (
        pb.FrameUpdate(states=[state("avatar")], events=[pb.GameEvent(kind=pb.EVENT_CUSTOM)]),
        grpc.StatusCode.INVALID_ARGUMENT,
    ),
    "player stats in a session without players": (
        pb.FrameUpdate(player_stats=[pb.PlayerStats(id="avatar")]),
        grpc.StatusCode.INVALID_ARGUMENT,
    ),
}


@pytest.mark.parametrize("case", REFUSALS)
def test_each_refusal_has_the_python_codecs_status_and_message(case):
    msg, status = REFUSALS[case]
    payload = msg.SerializeToString()
    want = python(payload)
    assert isinstance(want, tuple) and want[0] == status, want
    assert wire(payload) == want


def test_the_refusals_name_the_id_as_python_quotes_it():
    assert wire(pb.FrameUpdate(frame=3, states=[state("gh'o\"st")]).SerializeToString()) == (
        grpc.StatusCode.NOT_FOUND,
        "unknown object id 'gh\\'o\"st' in frame 3",
    )
    assert wire(pb.FrameUpdate(packed_ids=["nl\nid"], packed_transforms=[0.0] * 10).SerializeToString()) == (
        grpc.StatusCode.INVALID_ARGUMENT,
        "packed state 'nl\\nid' rotation is a zero-length quaternion",
    )


def test_a_frame_with_game_input_goes_through_the_python_codec():
    events = [pb.GameEvent(kind=pb.EVENT_KILL, actor_id="avatar", other_actor_id="box-1", time_s=1.0)]
    msg = pb.FrameUpdate(
        session_id="s",
        frame=4,
        time_s=2.0,
        states=[state("avatar", position=pb.Vec3(x=1.0))],
        events=events,
        player_stats=[pb.PlayerStats(id="box-1", health=50)],
    )
    payload = msg.SerializeToString()
    want = python(payload, PLAYERS)
    assert isinstance(want, FrameInput) and len(want.events) == 1 and len(want.player_stats) == 1
    assert_same(wire(payload, PLAYERS), want)
    assert native.decode_frame(payload, MOVABLE, STATIC, RigidTransform) is None


# -- the same over bytes that protobuf's own writer never makes ---------------------------------

VARINT, I64, LEN, I32 = 0, 1, 2, 5


def varint(value: int) -> bytes:
    out = bytearray()
    while value >= 0x80:
        out.append(value & 0x7F | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def field(number: int, wire_type: int, value: bytes | int) -> bytes:
    """One field on the wire: a varint's value an int, the others' their bytes (a length-delimited
    field's without its length)."""
    tag = varint(number << 3 | wire_type)
    if wire_type == VARINT:
        assert isinstance(value, int)
        return tag + varint(value)
    assert isinstance(value, bytes)
    return tag + (varint(len(value)) + value if wire_type == LEN else value)


# Known fields of another wire type than their own, which upb keeps among the unknown fields
FRAME_MISMATCHES = [(1, VARINT), (2, I64), (2, LEN), (3, VARINT), (3, I32), (3, LEN), (4, VARINT), (5, I64), (6, I32), (9, I64)]
OBJECT_STATE_MISMATCHES = [(1, VARINT), (1, I64), (2, VARINT), (2, I32)]
TRANSFORM_MISMATCHES = [(1, I64), (2, VARINT), (3, I32)]
VEC_MISMATCHES = [(1, VARINT), (2, I32), (3, LEN), (4, VARINT)]  # a Vec3's or a Quat's


@st.composite
def stray_fields(draw, mismatches: list[tuple[int, int]]) -> bytes:
    """Fields a reader of a message skips: unknown numbers, or known ones of another wire type."""
    unknown = st.tuples(st.sampled_from([10, 15, 16, 100, 2**29 - 1]), st.sampled_from([VARINT, I64, LEN, I32]))
    out = b""
    for _ in range(draw(st.integers(0, 3))):
        number, wire_type = draw(st.one_of(unknown, st.sampled_from(mismatches)))
        size = {I64: 8, I32: 4}.get(wire_type, draw(st.integers(0, 12)))
        value = draw(st.integers(0, 2**64 - 1)) if wire_type == VARINT else draw(st.binary(min_size=size, max_size=size))
        out += field(number, wire_type, value)
    return out


@st.composite
def merged_state(draw) -> bytes:
    """A `states` field whose ObjectState is two written one after the other, with stray fields
    between them: protobuf merges them (the second id wins when set; the transforms merge, part
    by part and number by number)."""
    first, second = draw(frames(good=True).filter(lambda f: len(f.states) >= 2)).states[:2]
    if draw(st.booleans()):
        second.ClearField("id")
    inner = first.SerializeToString() + draw(stray_fields(OBJECT_STATE_MISMATCHES)) + second.SerializeToString()
    return field(4, LEN, inner)


@st.composite
def strayed_state(draw) -> bytes:
    """A `states` field whose transform, and each part of it, hold stray fields, each part maybe
    given twice (merged number by number)."""
    (state,) = draw(frames(good=True).filter(lambda f: len(f.states) >= 1)).states[:1]
    transform = b""
    for number, name in ((1, "position"), (2, "rotation"), (3, "scale")):
        if state.transform.HasField(name):
            part = getattr(state.transform, name).SerializeToString()
            transform += field(number, LEN, part + draw(stray_fields(VEC_MISMATCHES)))
            if draw(st.booleans()):
                again = draw(st.sampled_from([b"", part[: len(part) // 9 * 9]]))  # none, or the first numbers again
                transform += field(number, LEN, again)
        transform += draw(stray_fields(TRANSFORM_MISMATCHES))
    return field(4, LEN, field(1, LEN, state.id.encode()) + field(2, LEN, transform))


@st.composite
def unpacked(draw) -> bytes:
    """packed ids with their values written one double a field, not packed."""
    msg = draw(frames(good=True))
    ids = b"".join(field(5, LEN, i.encode()) for i in msg.packed_ids)
    return ids + b"".join(field(6, I64, struct.pack("<d", x)) for x in msg.packed_transforms)


@FAST
@given(
    st.lists(
        st.one_of(
            frames(good=True).map(lambda f: f.SerializeToString()),
            merged_state(),
            strayed_state(),
            unpacked(),
            stray_fields(FRAME_MISMATCHES),
            st.builds(lambda n: field(2, VARINT, n), st.integers(2**64, 2**70 - 1)),  # a frame past 64 bits: truncated
        ),
        min_size=1,
        max_size=4,
    )
)
def test_merged_unpacked_and_unknown_fields_decode_as_upb_reads_them(pieces):
    payload = b"".join(pieces)
    want = python(payload)
    assert_same(wire(payload), want)


# -- encode --------------------------------------------------------------------------------------

double = st.one_of(finite, st.sampled_from([0.0, -0.0, NAN, INF, -INF, 5e-324]))
keys = st.text(max_size=10)


@st.composite
def states(draw) -> FrameState:
    """A FrameState without a MATCH part, every field the reply reads drawn."""
    out = FrameState(frame=draw(st.integers(0, 2**64 - 1)), time_s=draw(double), dt_s=0.0)
    if draw(st.booleans()):
        out.pose = CameraPose(np.array(draw(st.tuples(*[double] * 3))), np.array(draw(st.tuples(*[double] * 4))), draw(double))
    out.cut = draw(st.booleans())
    out.shot_id = draw(st.integers(0, 2**32 - 1))
    out.visibility = draw(double)
    out.flags = draw(st.lists(st.text(max_size=20), max_size=4))
    out.stage_ms = draw(st.dictionaries(keys, double, max_size=6))
    out.scores = draw(st.dictionaries(keys, double, max_size=3))
    if draw(st.booleans()):
        torus = make_torus((0.0, 0.0, 0.0), (2.0, 0.0, 0.0), draw(st.floats(0.05, 3.0))) if draw(st.booleans()) else None
        out.toric = ToricFrame(torus=torus, theta=draw(double), phi=draw(double))
    return out


def prefixed(keys) -> bool:
    """Whether a key is a proper prefix of another (upb's deterministic order puts it after)."""
    return any(a != b and b.encode().startswith(a.encode()) for a in keys for b in keys)


@FAST
@given(states(), double)
def test_a_reply_is_the_bytes_of_the_python_codecs(frame_state, compute_ms):
    reply = codec.camera_update_wire(frame_state)
    assert reply.stale is False and reply.compute_ms == 0.0
    reply.compute_ms = compute_ms
    got = reply.SerializeToString()
    want = codec.camera_update_msg(frame_state, compute_ms=compute_ms)
    assert pb.CameraUpdate.FromString(got).SerializeToString(deterministic=True) == want.SerializeToString(deterministic=True)
    if not (prefixed(frame_state.stage_ms) or prefixed(frame_state.scores)):
        assert got == want.SerializeToString(deterministic=True)
    if len(frame_state.stage_ms) <= 1 and len(frame_state.scores) <= 1:
        assert got == want.SerializeToString()  # what the Python path sends


def test_a_match_state_is_the_python_codecs():
    frame_state = FrameState(frame=1, time_s=0.0, dt_s=0.0, match=MatchFrame(players=(("p0", 0),), buffering=True))
    with pytest.raises(ValueError, match="MATCH part"):
        codec.camera_update_wire(frame_state)
