"""The C++ SDK's Unity and Unreal conversions against the Python SDK's, on the same numbers: both
directions, both engines, camera poses, fields of view, mesh vertices and winding."""

from __future__ import annotations

import numpy as np
import pytest

import camdirector_client as cd
from camdirector_client import convert
from tests.client_sdk.cpp.conftest import run_json


@pytest.fixture(scope="module")
def rows() -> np.ndarray:
    """(n, 12): position, unit quaternion (x, y, z, w), scale, vertical fov (deg), aspect."""
    rng = np.random.default_rng(1)
    n = 40
    position = rng.normal(scale=[5.0, 2.0, 500.0], size=(n, 3))
    rotation = rng.normal(size=(n, 4))
    rotation /= np.linalg.norm(rotation, axis=1, keepdims=True)
    scale = rng.uniform(0.1, 4.0, size=(n, 3))
    fov = rng.uniform(5.0, 150.0, size=(n, 1))
    aspect = rng.uniform(0.3, 4.0, size=(n, 1))
    data = np.hstack([position, rotation, scale, fov, aspect])
    data[0] = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 50.0, 16 / 9]  # identity
    data[1] = [-1.5, 2.25, -300.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.5, 3.0, 90.0, 1.0]  # a half turn
    return data


@pytest.fixture(scope="module")
def cpp(sdk_bin, rows) -> dict:
    stdin = "\n".join(" ".join(repr(float(v)) for v in row) for row in rows) + "\n"
    return run_json(sdk_bin / "convert_check", stdin=stdin)


def _columns(entries: list[dict], key: str) -> np.ndarray:
    return np.array([e[key] for e in entries])


@pytest.mark.parametrize(
    "direction, position_fn, rotation_fn, scale_fn",
    [
        ("from_unity", convert.from_unity_position, convert.from_unity_rotation, convert.from_unity_scale),
        ("to_unity", convert.to_unity_position, convert.to_unity_rotation, convert.to_unity_scale),
        ("from_unreal", convert.from_unreal_position, convert.from_unreal_rotation, convert.from_unreal_scale),
        ("to_unreal", convert.to_unreal_position, convert.to_unreal_rotation, convert.to_unreal_scale),
    ],
)
def test_transforms_equal_the_python_sdks_bit_for_bit(cpp, rows, direction, position_fn, rotation_fn, scale_fn):
    out = cpp[direction]
    assert len(out) == len(rows)
    np.testing.assert_array_equal(_columns(out, "position"), position_fn(rows[:, 0:3]))
    np.testing.assert_array_equal(_columns(out, "rotation"), rotation_fn(rows[:, 3:7]))
    np.testing.assert_array_equal(_columns(out, "scale"), scale_fn(rows[:, 7:10]))


@pytest.mark.parametrize("engine", ["unity", "unreal"])
def test_whole_transform_helpers_match_the_per_part_converters(cpp, rows, engine):
    position_fn = convert.from_unity_position if engine == "unity" else convert.from_unreal_position
    rotation_fn = convert.from_unity_rotation if engine == "unity" else convert.from_unreal_rotation
    out = cpp[f"from_{engine}_transform"]
    np.testing.assert_array_equal(_columns(out, "position"), position_fn(rows[:, 0:3]))
    np.testing.assert_array_equal(_columns(out, "rotation"), rotation_fn(rows[:, 3:7]))


@pytest.mark.parametrize("engine", ["unity", "unreal"])
def test_camera_poses_equal_the_python_sdks(cpp, rows, engine):
    to_engine = cd.camera_pose_to_unity if engine == "unity" else cd.camera_pose_to_unreal
    for row, got in zip(rows, cpp[f"camera_{engine}"]):
        position, rotation = to_engine(cd.Pose(row[0:3], row[3:7], float(row[10])))
        np.testing.assert_array_equal(got["position"], position)
        np.testing.assert_array_equal(got["rotation"], rotation)


def test_fields_of_view_equal_the_python_sdks(cpp, rows):
    expected = [cd.horizontal_fov_deg(float(r[10]), float(r[11])) for r in rows]
    np.testing.assert_allclose(cpp["horizontal_fov_deg"], expected, rtol=1e-15, atol=0)
    np.testing.assert_allclose(cpp["vertical_fov_deg"], rows[:, 10], rtol=1e-12)  # horizontal and back


@pytest.mark.parametrize("engine", ["unity", "unreal"])
def test_mesh_vertices_and_winding_equal_the_python_sdks(cpp, rows, engine):
    vertices32 = rows[:, 0:3].astype(np.float32)
    position_fn = convert.from_unity_position if engine == "unity" else convert.from_unreal_position
    faces = np.array([[0, 1, 2], [3, 4, 5]])
    mesh = cd.mesh_from_arrays(position_fn(vertices32), faces, flip_winding=True)
    np.testing.assert_array_equal(
        np.array(cpp[f"{engine}_vertices"], dtype=np.float32), np.array(mesh.triangles.vertices, dtype=np.float32)
    )
    assert cpp["flipped"] == list(mesh.triangles.indices)


def test_round_trips_are_identities(cpp, rows):
    """to(from(x)) on the C++ side's numbers: the two directions are inverses."""
    for engine in ("unity", "unreal"):
        back = (convert.to_unity_position if engine == "unity" else convert.to_unreal_position)(
            _columns(cpp[f"from_{engine}"], "position")
        )
        np.testing.assert_allclose(back, rows[:, 0:3], rtol=1e-15, atol=1e-12)
        back_q = (convert.to_unity_rotation if engine == "unity" else convert.to_unreal_rotation)(
            _columns(cpp[f"from_{engine}"], "rotation")
        )
        np.testing.assert_array_equal(back_q, rows[:, 3:7])


def test_the_c_interface_compiles_and_links_as_c(sdk_bin):
    """tools/c_api_check.c: camdirector.h as C99, the static library linked from a C program."""
    report = run_json(sdk_bin / "c_api_check")
    assert report["bad_address"] == "INVALID_ARGUMENT" and "no port" in report["reason"]
    assert report["good_address"] == "OK"
    assert report["hfov_deg"] == cd.horizontal_fov_deg(50.0, 16 / 9)
