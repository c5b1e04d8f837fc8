"""camdirector_client.convert: round trips, handedness, units, camera conventions, packing."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import camdirector_client as cd
from camdirector.v1 import director_pb2 as pb

# Per test, not a global profile: other suites in the same run keep their own settings.
quick = settings(deadline=None, max_examples=60)

# --- reference quaternion maths, written independently of the SDK ------------------------------


def hamilton(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v' = q v q* for a unit quaternion (x, y, z, w)."""
    conjugate = np.array([-q[0], -q[1], -q[2], q[3]])
    return hamilton(hamilton(q, np.append(v, 0.0)), conjugate)[:3]


def axis_angle(axis, angle_deg: float) -> np.ndarray:
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    half = math.radians(angle_deg) / 2.0
    return np.append(axis * math.sin(half), math.cos(half))


def same_rotation(a: np.ndarray, b: np.ndarray) -> bool:
    return np.allclose(a, b, atol=1e-9) or np.allclose(a, -b, atol=1e-9)


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


# --- strategies --------------------------------------------------------------------------------

coords = st.floats(-1e5, 1e5, allow_nan=False)
vectors = hnp.arrays(np.float64, 3, elements=coords)
vector_batches = hnp.arrays(np.float64, st.tuples(st.integers(0, 8), st.just(3)), elements=coords)
scales = hnp.arrays(np.float64, 3, elements=st.floats(0.01, 100.0))
quaternions = (
    hnp.arrays(np.float64, 4, elements=st.floats(-1.0, 1.0))
    .filter(lambda q: np.linalg.norm(q) > 0.1)
    .map(lambda q: q / np.linalg.norm(q))
)
quaternion_batches = (
    hnp.arrays(np.float64, st.tuples(st.integers(0, 8), st.just(4)), elements=st.floats(-1.0, 1.0))
    .filter(lambda q: bool(np.all(np.linalg.norm(q, axis=-1) > 0.1)))
    .map(lambda q: q / np.linalg.norm(q, axis=-1, keepdims=True))
)

ENGINES = {
    "unity": (
        cd.from_unity_position,
        cd.to_unity_position,
        cd.from_unity_rotation,
        cd.to_unity_rotation,
        cd.from_unity_scale,
        cd.to_unity_scale,
        1.0,
    ),
    "unreal": (
        cd.from_unreal_position,
        cd.to_unreal_position,
        cd.from_unreal_rotation,
        cd.to_unreal_rotation,
        cd.from_unreal_scale,
        cd.to_unreal_scale,
        100.0,
    ),
}
engine_names = st.sampled_from(sorted(ENGINES))


def engine_direction_to_ours(engine: str, v: np.ndarray) -> np.ndarray:
    from_position, *_, units_per_m = ENGINES[engine]
    return from_position(v) * units_per_m


def ours_direction_to_engine(engine: str, v: np.ndarray) -> np.ndarray:
    _, to_position, *_, units_per_m = ENGINES[engine]
    return to_position(v) / units_per_m


# --- round trips -------------------------------------------------------------------------------


@quick
@given(engine_names, st.one_of(vectors, vector_batches))
def test_position_round_trips(engine, v):
    from_position, to_position, *_ = ENGINES[engine]
    assert to_position(from_position(v)).shape == v.shape
    np.testing.assert_allclose(to_position(from_position(v)), v, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(from_position(to_position(v)), v, rtol=1e-12, atol=1e-9)


@quick
@given(engine_names, st.one_of(quaternions, quaternion_batches))
def test_rotation_round_trips_exactly(engine, q):
    _, _, from_rotation, to_rotation, *_ = ENGINES[engine]
    np.testing.assert_array_equal(to_rotation(from_rotation(q)), q)
    np.testing.assert_array_equal(from_rotation(to_rotation(q)), q)


@quick
@given(engine_names, st.one_of(scales, vector_batches))
def test_scale_round_trips_exactly(engine, s):
    *_, from_scale, to_scale, _ = ENGINES[engine]
    np.testing.assert_array_equal(to_scale(from_scale(s)), s)
    np.testing.assert_array_equal(from_scale(to_scale(s)), s)


@quick
@given(engine_names, vector_batches, quaternion_batches)
def test_batches_convert_row_by_row(engine, v, q):
    from_position, _, from_rotation, *_ = ENGINES[engine]
    for row in range(len(v)):
        np.testing.assert_array_equal(from_position(v)[row], from_position(v[row]))
    for row in range(len(q)):
        np.testing.assert_array_equal(from_rotation(q)[row], from_rotation(q[row]))


@pytest.mark.parametrize("engine", sorted(ENGINES))
def test_converters_reject_bad_shapes(engine):
    from_position, _, from_rotation, *_ = ENGINES[engine]
    with pytest.raises(ValueError, match=r"\(3,\) or \(n, 3\)"):
        from_position([1.0, 2.0])
    with pytest.raises(ValueError, match=r"\(4,\) or \(n, 4\)"):
        from_rotation(np.zeros((2, 2, 4)))


# --- handedness and consistency ----------------------------------------------------------------


@quick
@given(engine_names, quaternions, vectors, vectors, scales)
def test_transforms_map_consistently(engine, q, position, local, scale):
    """world = p + R (s * local) in the engine's frame is the same point in ours."""
    from_position, _, from_rotation, _, from_scale, _, _ = ENGINES[engine]
    world_engine = position + rotate(q, scale * local)
    world_ours = from_position(position) + rotate(from_rotation(q), from_scale(scale) * from_position(local))
    np.testing.assert_allclose(from_position(world_engine), world_ours, rtol=1e-9, atol=1e-6)


@quick
@given(engine_names, quaternions)
def test_converted_rotations_are_proper_rotations(engine, q):
    _, _, from_rotation, *_ = ENGINES[engine]
    assert np.linalg.norm(from_rotation(q)) == pytest.approx(1.0)
    assert np.linalg.det(cd.rotation_matrix(from_rotation(q))) == pytest.approx(1.0)


def test_unity_yaw_right_turns_our_forward_right():
    yaw_90 = axis_angle([0, 1, 0], 90.0)
    # In Unity, +90 degrees about +Y turns forward (+Z) toward +X (right).
    np.testing.assert_allclose(rotate(yaw_90, np.array([0.0, 0.0, 1.0])), [1, 0, 0], atol=1e-12)
    ours = cd.from_unity_rotation(yaw_90)
    forward_ours = cd.from_unity_position([0.0, 0.0, 1.0])
    np.testing.assert_allclose(forward_ours, [0, 0, -1])
    np.testing.assert_allclose(rotate(ours, forward_ours), cd.from_unity_position([1.0, 0.0, 0.0]), atol=1e-12)
    np.testing.assert_allclose(rotate(ours, forward_ours), [1, 0, 0], atol=1e-12)  # our camera's right
    # Turning right, seen from above in a right-handed +Y-up frame, is clockwise: -90 about +Y.
    assert same_rotation(ours, axis_angle([0, 1, 0], -90.0))


def test_unreal_yaw_right_turns_our_forward_right():
    yaw_90 = axis_angle([0, 0, 1], 90.0)
    # In Unreal, +90 degrees of yaw (about +Z) turns forward (+X) toward +Y (right).
    np.testing.assert_allclose(rotate(yaw_90, np.array([1.0, 0.0, 0.0])), [0, 1, 0], atol=1e-12)
    ours = cd.from_unreal_rotation(yaw_90)
    np.testing.assert_allclose(rotate(ours, np.array([0.0, 0.0, -1.0])), [1, 0, 0], atol=1e-12)
    # The same physical turn as Unity's +90 degrees about its up axis.
    assert same_rotation(ours, cd.from_unity_rotation(axis_angle([0, 1, 0], 90.0)))


def test_unreal_pitch_up_tilts_our_forward_up():
    # An FQuat of -30 degrees about Unreal's +Y (right) tilts forward (+X) up (+Z): FRotator pitch +30.
    pitch_up = axis_angle([0, 1, 0], -30.0)
    forward_ue = rotate(pitch_up, np.array([1.0, 0.0, 0.0]))
    assert forward_ue[2] > 0.0
    ours = cd.from_unreal_rotation(pitch_up)
    forward = rotate(ours, np.array([0.0, 0.0, -1.0]))
    np.testing.assert_allclose(forward, [0.0, math.sin(math.radians(30)), -math.cos(math.radians(30))], atol=1e-12)


def test_unreal_axes_and_centimetres():
    np.testing.assert_allclose(cd.from_unreal_position([100.0, 0.0, 0.0]), [0, 0, -1])  # forward
    np.testing.assert_allclose(cd.from_unreal_position([0.0, 100.0, 0.0]), [1, 0, 0])  # right
    np.testing.assert_allclose(cd.from_unreal_position([0.0, 0.0, 100.0]), [0, 1, 0])  # up
    np.testing.assert_allclose(cd.from_unreal_position([250.0, -40.0, 1.0]), [-0.4, 0.01, -2.5])
    np.testing.assert_allclose(cd.to_unreal_position([1.0, 2.0, 3.0]), [-300.0, 100.0, 200.0])
    np.testing.assert_array_equal(cd.from_unreal_scale([2.0, 3.0, 4.0]), [3.0, 4.0, 2.0])  # no unit change


def test_unreal_to_unity_matches_the_usual_engine_mapping():
    # Unity (x, y, z) = Unreal (y, z, x) / 100: right, up, forward in both.
    np.testing.assert_allclose(cd.to_unity_position(cd.from_unreal_position([100.0, 200.0, 300.0])), [2, 3, 1])
    np.testing.assert_array_equal(cd.to_unity_scale(cd.from_unreal_scale([1.0, 2.0, 3.0])), [2, 3, 1])


def test_unity_axes():
    np.testing.assert_array_equal(cd.from_unity_position([1.0, 2.0, 3.0]), [1, 2, -3])
    np.testing.assert_array_equal(cd.from_unity_rotation([0.1, 0.2, 0.3, 0.9]), [-0.1, -0.2, 0.3, 0.9])
    np.testing.assert_array_equal(cd.from_unity_scale([1.0, 2.0, 3.0]), [1, 2, 3])


# --- cameras -----------------------------------------------------------------------------------

ENGINE_CAMERA_AXES = {  # forward, up, right of a camera in the engine's local frame
    "unity": ([0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]),
    "unreal": ([1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]),
}
CAMERA_POSE_TO = {"unity": cd.camera_pose_to_unity, "unreal": cd.camera_pose_to_unreal}


@quick
@given(engine_names, quaternions, vectors)
def test_engine_camera_converts_to_our_camera(engine, q, position):
    """An engine camera, converted, looks where it looked, with the same up and right."""
    from_position, _, from_rotation, *_ = ENGINES[engine]
    forward, up, right = (np.array(a) for a in ENGINE_CAMERA_AXES[engine])
    pose = cd.Pose(from_position(position), from_rotation(q), 50.0)
    np.testing.assert_allclose(pose.forward, unit(engine_direction_to_ours(engine, rotate(q, forward))), atol=1e-9)
    np.testing.assert_allclose(pose.up, unit(engine_direction_to_ours(engine, rotate(q, up))), atol=1e-9)
    np.testing.assert_allclose(pose.right, unit(engine_direction_to_ours(engine, rotate(q, right))), atol=1e-9)


@quick
@given(engine_names, quaternions, vectors)
def test_camera_pose_to_engine(engine, q, position):
    """The engine camera returned looks along our forward with our up, from our position."""
    pose = cd.Pose(position, q, 40.0)
    position_engine, q_engine = CAMERA_POSE_TO[engine](pose)
    forward, up, _ = (np.array(a) for a in ENGINE_CAMERA_AXES[engine])
    np.testing.assert_allclose(unit(rotate(q_engine, forward)), unit(ours_direction_to_engine(engine, pose.forward)), atol=1e-9)
    np.testing.assert_allclose(unit(rotate(q_engine, up)), unit(ours_direction_to_engine(engine, pose.up)), atol=1e-9)
    from_position, *_ = ENGINES[engine]
    np.testing.assert_allclose(from_position(position_engine), position, rtol=1e-12, atol=1e-9)


def test_camera_pose_to_unreal_example():
    # Our camera 1 m up, turned 90 degrees left (looking along our -X).
    update = pb.CameraUpdate()
    update.pose.position.y = 1.0
    update.pose.rotation.CopyFrom(cd.quat(axis_angle([0, 1, 0], 90.0)))
    update.pose.vertical_fov_deg = 50.0
    np.testing.assert_allclose(cd.pose_from_msg(update.pose).forward, [-1, 0, 0], atol=1e-12)
    position_cm, q_ue = cd.camera_pose_to_unreal(update.pose)
    np.testing.assert_allclose(position_cm, [0, 0, 100])
    np.testing.assert_allclose(rotate(q_ue, np.array([1.0, 0.0, 0.0])), [0, -1, 0], atol=1e-12)  # Unreal's left
    assert same_rotation(q_ue, axis_angle([0, 0, 1], -90.0))  # yaw -90
    position_u, q_u = cd.camera_pose_to_unity(update.pose)
    np.testing.assert_allclose(position_u, [0, 1, 0])
    np.testing.assert_allclose(rotate(q_u, np.array([0.0, 0.0, 1.0])), [-1, 0, 0], atol=1e-12)  # Unity's left


def test_horizontal_fov():
    assert cd.horizontal_fov_deg(90.0, 1.0) == pytest.approx(90.0)
    assert cd.horizontal_fov_deg(60.0, 16 / 9) == pytest.approx(91.4928, abs=1e-3)


# --- Pose --------------------------------------------------------------------------------------


@quick
@given(quaternions, vectors, vectors)
def test_pose_matrix_matches_rotation(q, position, local):
    pose = cd.Pose(position, q, 50.0)
    m = pose.matrix()
    assert m.shape == (4, 4)
    np.testing.assert_array_equal(m[3], [0, 0, 0, 1])
    np.testing.assert_allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.linalg.det(m[:3, :3]) == pytest.approx(1.0)
    np.testing.assert_allclose((m @ np.append(local, 1.0))[:3], position + rotate(q, local), rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(pose.forward, rotate(q, np.array([0.0, 0.0, -1.0])), atol=1e-12)
    np.testing.assert_allclose(pose.up, rotate(q, np.array([0.0, 1.0, 0.0])), atol=1e-12)
    np.testing.assert_allclose(np.cross(pose.right, pose.up), -pose.forward, atol=1e-12)  # right-handed


def test_pose_from_msg():
    msg = pb.CameraPose(position=cd.vec3([1, 2, 3]), rotation=cd.quat([0, 0, 0, 2]), vertical_fov_deg=35.0)
    pose = cd.pose_from_msg(msg)
    np.testing.assert_array_equal(pose.position, [1, 2, 3])
    np.testing.assert_array_equal(pose.rotation_xyzw, [0, 0, 0, 1])  # normalised
    assert pose.vertical_fov_deg == 35.0
    np.testing.assert_array_equal(cd.pose_from_msg(pb.CameraPose()).rotation_xyzw, [0, 0, 0, 1])  # unset


@quick
@given(quaternion_batches)
def test_rotation_matrix_batches(q):
    m = cd.rotation_matrix(q)
    assert m.shape == (len(q), 3, 3)
    for row in range(len(q)):
        np.testing.assert_allclose(m[row] @ [1.0, 2.0, 3.0], rotate(q[row], np.array([1.0, 2.0, 3.0])), atol=1e-12)


# --- messages ----------------------------------------------------------------------------------


def test_transform_msg_leaves_defaults_unset():
    msg = cd.transform_msg([1, 2, 3])
    assert (msg.position.x, msg.position.y, msg.position.z) == (1, 2, 3)
    assert not msg.HasField("rotation") and not msg.HasField("scale")
    msg = cd.transform_msg(np.array([0.0, 0.0, 0.0]), np.array([0.0, 0.0, 0.6, 0.8]), (2, 2, 2))
    assert (msg.rotation.z, msg.rotation.w) == (0.6, 0.8)
    assert msg.scale.y == 2.0


def test_mesh_from_arrays():
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    mesh = cd.mesh_from_arrays(vertices, faces)
    assert mesh.WhichOneof("source") == "triangles"
    np.testing.assert_array_equal(np.reshape(mesh.triangles.vertices, (-1, 3)), vertices)
    np.testing.assert_array_equal(np.reshape(mesh.triangles.indices, (-1, 3)), faces)
    flipped = cd.mesh_from_arrays(vertices, faces, flip_winding=True)
    np.testing.assert_array_equal(np.reshape(flipped.triangles.indices, (-1, 3)), [[0, 2, 1], [0, 3, 2]])


def test_mesh_from_arrays_rejects_bad_input():
    with pytest.raises(ValueError, match=r"vertices must be \(n, 3\)"):
        cd.mesh_from_arrays(np.zeros((3, 2)), [[0, 1, 2]])
    with pytest.raises(ValueError, match=r"faces must be \(m, 3\)"):
        cd.mesh_from_arrays(np.zeros((3, 3)), [0, 1, 2])
    with pytest.raises(ValueError, match="faces must index vertices"):
        cd.mesh_from_arrays(np.zeros((3, 3)), [[0, 1, 3]])
    with pytest.raises(ValueError, match="integers"):
        cd.mesh_from_arrays(np.zeros((3, 3)), [[0.0, 1.0, 2.0]])


def test_unity_mesh_keeps_its_facing_after_conversion():
    """A Unity front face (clockwise seen from the front) stays front-facing for us (counter-clockwise)."""
    vertices_u = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # clockwise seen from -Z (front)
    mesh = cd.mesh_from_arrays(cd.from_unity_position(vertices_u), [[0, 1, 2]], flip_winding=True)
    a, b, c = np.reshape(mesh.triangles.vertices, (-1, 3))[list(mesh.triangles.indices)]
    normal = np.cross(b - a, c - a)  # counter-clockwise normal, ours
    viewer = cd.from_unity_position([0.0, 0.0, -1.0])  # where Unity's camera saw it from
    assert normal @ (viewer - a) > 0.0


def test_pack_states_layout():
    ids, packed = cd.pack_states(
        ["a", "b"],
        [[1, 2, 3], [4, 5, 6]],
        [[0, 0, 0, 1], [0.6, 0, 0, 0.8]],
        [[7, 8, 9], [1, 1, 2]],
    )
    assert ids == ["a", "b"]
    assert packed.dtype == np.float64 and packed.shape == (20,)
    np.testing.assert_array_equal(packed, [1, 2, 3, 0, 0, 0, 1, 7, 8, 9, 4, 5, 6, 0.6, 0, 0, 0.8, 1, 1, 2])
    _, unit_scales = cd.pack_states(["a"], [[1, 2, 3]], [[0, 0, 0, 1]])
    np.testing.assert_array_equal(unit_scales[7:], [1, 1, 1])
    assert cd.pack_states([], np.zeros((0, 3)), np.zeros((0, 4)))[1].shape == (0,)


@quick
@given(vector_batches, st.data())
def test_pack_states_round_trips_through_a_frame_update(positions, data):
    n = len(positions)
    rotations = data.draw(hnp.arrays(np.float64, (n, 4), elements=st.floats(-1, 1)))
    scales_ = data.draw(hnp.arrays(np.float64, (n, 3), elements=st.floats(0.1, 10)))
    ids = [f"obj{i}" for i in range(n)]
    packed_ids, packed = cd.pack_states(ids, positions, rotations, scales_)
    update = pb.FrameUpdate(packed_ids=packed_ids, packed_transforms=packed.tolist())
    update = pb.FrameUpdate.FromString(update.SerializeToString())
    got_ids, p, q, s = cd.unpack_states(update.packed_ids, update.packed_transforms)
    assert got_ids == ids
    np.testing.assert_array_equal(p, positions.reshape(n, 3))
    np.testing.assert_array_equal(q, rotations)
    np.testing.assert_array_equal(s, scales_)


def test_pack_states_rejects_bad_input():
    with pytest.raises(ValueError, match=r"positions must be \(2, 3\)"):
        cd.pack_states(["a", "b"], [[1, 2, 3]], [[0, 0, 0, 1]] * 2)
    with pytest.raises(ValueError, match=r"rotations must be \(1, 4\)"):
        cd.pack_states(["a"], [[1, 2, 3]], [[0, 0, 1]])
    with pytest.raises(ValueError, match=r"scales must be \(1, 3\)"):
        cd.pack_states(["a"], [[1, 2, 3]], [[0, 0, 0, 1]], [1, 1, 1])
    with pytest.raises(TypeError, match="strings"):
        cd.pack_states([1], [[1, 2, 3]], [[0, 0, 0, 1]])
