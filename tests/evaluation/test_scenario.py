"""Scenario files: what loads, what is refused with which message, and how keyframes interpolate."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from camdirector.evaluation.scenario import PARK_OFFSET_M
from camdirector.evaluation.scenario_file import ScenarioError, load_scenario, parse_scenario
from camdirector.evaluation.scenario_motion import BounceMotion, KeyframedMotion
from camdirector.evaluation.scenario_schema import FORMAT
from camdirector.v1 import director_pb2 as pb


def tiny(**overrides) -> dict:
    """A valid one-target scenario: a sphere standing still for 1 s at 10 Hz."""
    doc = {
        "format": FORMAT,
        "name": "tiny",
        "duration_s": 1.0,
        "frame_rate_hz": 10,
        "targets": [{"id": "t", "shape": {"sphere": {"radius": 0.5}}, "position": [0.0, 1.0, 0.0]}],
    }
    doc.update(overrides)
    return doc


def write(tmp_path, doc, name="case.json"):
    path = tmp_path / name
    path.write_text(json.dumps(doc) if not isinstance(doc, str) else doc)
    return path


def motion(**fields) -> dict:
    return {"id": "t", "shape": {"sphere": {"radius": 0.5}}, "motion": fields}


# --------------------------------------------------------------------------------------------
# valid files


def test_minimal_file_loads_with_defaults(tmp_path):
    s = load_scenario(write(tmp_path, tiny()))
    assert (s.name, s.seed, s.lens, s.style, s.objects) == ("tiny", 0, {}, {}, [])
    assert np.allclose(s.frame_times(), np.arange(11) / 10)
    request = s.create_session_request()
    assert request.style.visibility == pb.FRAMING_ONLY
    assert request.targets[0].mesh.primitive.sphere.radius == 0.5
    assert request.lens.vertical_fov_deg == 0.0  # unset: the server's default


def test_every_field_reaches_the_request(tmp_path):
    doc = tiny(
        seed=7,
        lens={"vertical_fov_deg": 40, "aspect": 1.5},
        style={
            "screen_a": [-0.4, 0.1],
            "screen_b": [0.3, 0.0],
            "visibility": "raycast",
            "gaze_room_m": 3.0,
            "preferred_phi_deg": 60,
            "max_speed_m_s": 5.0,
        },
        objects=[
            {"id": "crate", "shape": {"box": {"size": [1, 2, 3]}}, "position": [1, 1, 1], "yaw_deg": 90, "scale": [1, 2, 1]},
            {"id": "pole", "shape": {"cylinder": {"radius": 0.2, "height": 3}}, "dynamic": True},
            {"id": "pill", "shape": {"capsule": {"radius": 0.3, "height": 1.8}}, "rotation": [0, 0, 0, 2]},
        ],
    )
    doc["targets"][0]["aim_offset"] = [0, 0.5, 0]
    s = load_scenario(write(tmp_path, doc))
    r = s.create_session_request()
    assert r.seed == 7 and r.lens.vertical_fov_deg == 40 and r.lens.aspect == 1.5
    assert r.style.visibility == pb.RAYCAST and r.style.gaze_room_m == 3.0 and r.style.max_speed_m_s == 5.0
    assert (r.style.screen_a.x, r.style.screen_a.y) == pytest.approx((-0.4, 0.1))
    assert not r.style.HasField("response_time_s")
    crate, pole, pill = r.objects
    assert (crate.mesh.primitive.box.size.y, crate.transform.scale.y, crate.dynamic) == (2, 2, False)
    assert crate.transform.rotation.y == pytest.approx(math.sin(math.pi / 4))
    assert pole.dynamic and pole.mesh.primitive.cylinder.height == 3
    assert pill.transform.rotation.w == pytest.approx(1.0)  # normalised
    assert r.targets[0].aim_offset.y == 0.5
    assert s.create_session_request("ANTICIPATION").style.visibility == pb.ANTICIPATION
    assert s.create_session_request(pb.FRAMING_ONLY).style.visibility == pb.FRAMING_ONLY


def test_mesh_files_are_sent_as_obj_or_glb_relative_to_the_scenario(tmp_path):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "quad.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nf 1 2 3 4\n")
    trimesh.creation.box(extents=(1, 1, 1)).export(tmp_path / "meshes" / "box.glb")
    (tmp_path / "scenarios").mkdir()
    doc = tiny(
        objects=[
            {"id": "floor", "shape": {"mesh": {"path": "../meshes/quad.obj", "scale": 2.0}}},
            {"id": "crate", "shape": {"mesh": {"path": "../meshes/box.glb"}}, "scale": 3},
        ]
    )
    s = load_scenario(write(tmp_path / "scenarios", doc))
    floor, crate = s.create_session_request().objects
    assert floor.mesh.obj.startswith(b"v 0 0 0") and floor.transform.scale.x == 2.0
    assert crate.mesh.glb[:4] == b"glTF" and crate.transform.scale.z == 3.0
    assert s.objects[0].shape.mesh.triangle_count == 2


# --------------------------------------------------------------------------------------------
# invalid files, one message each


def _set(path, value):
    def edit(doc):
        node = doc
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value

    return edit


def _drop(key):
    return lambda doc: doc.pop(key)


INVALID = {
    "wrong format": (_set(["format"], "camdirector.scenario/2"), "format: must be 'camdirector.scenario/1'"),
    "missing duration": (_drop("duration_s"), "(top level): missing required key 'duration_s'"),
    "misspelt key": (_set(["durration_s"], 3), "(top level): unknown key 'durration_s'"),
    "zero duration": (_set(["duration_s"], 0), "duration_s: must be > 0"),
    "string rate": (_set(["frame_rate_hz"], "60"), "frame_rate_hz: must be a finite number"),
    "bad name": (_set(["name"], "a b"), "name: may hold only"),
    "three targets": (lambda d: d["targets"].extend(copy.deepcopy(d["targets"]) * 2), "one or two targets"),
    "unknown shape": (_set(["targets", 0, "shape"], {"cube": {"size": 1}}), "targets[0].shape: unknown shape 'cube'"),
    "two shapes": (_set(["targets", 0, "shape"], {"sphere": {"radius": 1}, "box": {}}), "exactly one of"),
    "negative radius": (_set(["targets", 0, "shape"], {"sphere": {"radius": -1}}), "targets[0].shape.sphere.radius: must be > 0"),
    "flat box": (_set(["targets", 0, "shape"], {"box": {"size": [1, 0, 1]}}), "targets[0].shape.box.size: must be positive"),
    "short capsule": (_set(["targets", 0, "shape"], {"capsule": {"radius": 1, "height": 1}}), "at least twice its radius"),
    "missing mesh": (_set(["targets", 0, "shape"], {"mesh": {"path": "nowhere.obj"}}), "'nowhere.obj' does not exist"),
    "not a mesh file": (_set(["targets", 0, "shape"], {"mesh": {"path": "case.json"}}), "is not an .obj or .glb file"),
    "position of two": (_set(["targets", 0, "position"], [1, 2]), "targets[0].position: must be a list of 3 numbers"),
    "yaw and rotation": (lambda d: d["targets"][0].update(yaw_deg=10, rotation=[0, 0, 0, 1]), "at most one of 'yaw_deg'"),
    "zero quaternion": (_set(["targets", 0, "rotation"], [0, 0, 0, 0]), "zero-length quaternion"),
    "keys not increasing": (
        _set(["targets", 0], motion(position_keys=[[0, 0, 0, 0], [0, 1, 0, 0]])),
        "targets[0].motion.position_keys[1]: key times must be strictly increasing",
    ),
    "key of three": (_set(["targets", 0], motion(position_keys=[[0, 0, 0]])), "position_keys[0]: must be a list of 4"),
    "keys and waypoints": (
        _set(["targets", 0], motion(position_keys=[[0, 0, 0, 0]], waypoints=[[0, 0, 0], [1, 0, 0]], speed_m_s=1)),
        "exactly one of 'position_keys' and 'waypoints'",
    ),
    "waypoints without speed": (
        _set(["targets", 0], motion(waypoints=[[0, 0, 0], [1, 0, 0]])),
        "targets[0].motion: missing required key 'speed_m_s'",
    ),
    "repeated waypoint": (
        _set(["targets", 0], motion(waypoints=[[0, 0, 0], [0, 0, 0]], speed_m_s=1)),
        "waypoints[1]: repeats the previous waypoint",
    ),
    "speed with keys": (_set(["targets", 0], motion(position_keys=[[0, 0, 0, 0]], speed_m_s=1)), "only goes with 'waypoints'"),
    "unknown interpolation": (
        _set(["targets", 0], motion(position_keys=[[0, 0, 0, 0]], interpolation="bezier")),
        "interpolation: must be 'linear' or 'catmull_rom'",
    ),
    "open loop": (
        _set(["targets", 0], motion(position_keys=[[0, 0, 0, 0], [1, 1, 0, 0], [2, 2, 0, 0]], loop=True)),
        "must end where it starts",
    ),
    "two orientations": (
        _set(["targets", 0], motion(position_keys=[[0, 0, 0, 0]], orient="path", yaw_keys=[[0, 0]])),
        "at most one of yaw_keys, rotation_keys, orient",
    ),
    "unknown orient": (_set(["targets", 0], motion(position_keys=[[0, 0, 0, 0]], orient="target")), "orient: must be 'path'"),
    "static object moving": (
        _set(["objects"], [{"id": "o", "shape": {"sphere": {"radius": 1}}, "motion": {"position_keys": [[0, 0, 0, 0]]}}]),
        "objects[0].motion: a static object cannot move",
    ),
    "static object spawning": (
        _set(["objects"], [{"id": "o", "shape": {"sphere": {"radius": 1}}, "spawn_s": 1}]),
        "objects[0].spawn_s: only a dynamic object can spawn",
    ),
    "aim offset on object": (
        _set(["objects"], [{"id": "o", "shape": {"sphere": {"radius": 1}}, "aim_offset": [0, 0, 0]}]),
        "objects[0]: unknown key 'aim_offset'",
    ),
    "duplicate id": (_set(["objects"], [{"id": "t", "shape": {"sphere": {"radius": 1}}}]), "id 't' is used twice"),
    "unknown mode": (_set(["style"], {"visibility": "XRAY"}), "style.visibility: unknown visibility mode 'XRAY'"),
    "screen point off screen": (_set(["style"], {"screen_a": [2, 0]}), "style.screen_a: must have x and y in [-1, 1]"),
    "fov out of range": (_set(["lens"], {"vertical_fov_deg": 180}), "lens.vertical_fov_deg: must be <= 170"),
    "unknown generator": (_set(["generators"], [{"kind": "rain"}]), "generators[0].kind: must be 'scatter' or 'spawn'"),
    "crowded scatter": (
        _set(
            ["generators"],
            [
                {
                    "kind": "scatter",
                    "id_prefix": "tree",
                    "count": 50,
                    "min_spacing_m": 5,
                    "region": {"x": [0, 10], "z": [0, 10]},
                    "parts": [{"shape": {"sphere": {"radius": 0.1}}}],
                }
            ],
        ),
        "generators[0]: placed only",
    ),
    "misspelt generator key": (
        _set(
            ["generators"],
            [
                {
                    "kind": "spawn",
                    "id_prefix": "c",
                    "count": 1,
                    "speed_m_s": [1, 2],
                    "region": {"x": [0, 5], "z": [0, 5]},
                    "spedd": 1,
                    "shape": {"sphere": {"radius": 0.1}},
                }
            ],
        ),
        "generators[0]: unknown key 'spedd'; expected one of batch, clear_of_targets_m",
    ),
    "string seed": (_set(["seed"], "7"), "seed: must be an integer, got '7'"),
    "inverted region": (
        _set(
            ["generators"],
            [
                {
                    "kind": "spawn",
                    "id_prefix": "c",
                    "count": 1,
                    "speed_m_s": [1, 2],
                    "region": {"x": [5, 0], "z": [0, 10]},
                    "shape": {"sphere": {"radius": 0.1}},
                }
            ],
        ),
        "generators[0].region.x: must be [min, max]",
    ),
}


@pytest.mark.parametrize("case", sorted(INVALID))
def test_invalid_file_is_refused_with_its_message(tmp_path, case):
    edit, message = INVALID[case]
    doc = tiny()
    edit(doc)
    with pytest.raises(ScenarioError) as info:
        load_scenario(write(tmp_path, doc))
    assert str(info.value).startswith("case.json: ")
    assert message in str(info.value)


def test_unreadable_and_malformed_files(tmp_path):
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path / "absent.json")
    with pytest.raises(ScenarioError, match=r"broken.json: not valid JSON: .* at line 2 column"):
        load_scenario(write(tmp_path, '{"format":\n  oops}', "broken.json"))
    with pytest.raises(ScenarioError, match=r"list.json: \(top level\): must be an object, got a list"):
        load_scenario(write(tmp_path, "[]", "list.json"))


def test_broken_obj_file_is_refused(tmp_path):
    (tmp_path / "bad.obj").write_text("v 0 0 0\nv nan 0 0\nv 0 0 1\nf 1 2 3\n")
    with pytest.raises(ScenarioError, match=r"targets\[0\].shape.mesh.path: 'bad.obj': "):
        load_scenario(write(tmp_path, tiny(targets=[{"id": "t", "shape": {"mesh": {"path": "bad.obj"}}}])))


# --------------------------------------------------------------------------------------------
# keyframes


def test_linear_keys_interpolate_and_hold_outside():
    m = KeyframedMotion(np.array([1.0, 3.0]), np.array([[0.0, 0.0, 0.0], [4.0, 2.0, 0.0]]))
    p = m.positions_at(np.array([0.0, 1.0, 2.0, 2.5, 3.0, 9.0]))
    assert np.allclose(p, [[0, 0, 0], [0, 0, 0], [2, 1, 0], [3, 1.5, 0], [4, 2, 0], [4, 2, 0]])


def test_catmull_rom_passes_through_keys_with_continuous_velocity():
    times = np.array([0.0, 1.0, 2.5, 3.0, 5.0])
    keys = np.array([[0, 0, 0], [1, 2, 0], [3, 1, 1], [4, 0, 2], [6, 1, 0]], dtype=float)
    m = KeyframedMotion(times, keys, "catmull_rom")
    assert np.allclose(m.positions_at(times), keys)
    h = 1e-6
    for t in times[1:-1]:
        left = (m.positions_at(np.array([t])) - m.positions_at(np.array([t - h]))) / h
        right = (m.positions_at(np.array([t + h])) - m.positions_at(np.array([t]))) / h
        assert np.allclose(left, right, atol=1e-4)
    # evenly spaced collinear keys: a straight line at constant speed
    line = KeyframedMotion(np.arange(4.0), np.array([[2.0 * i, 0, 0] for i in range(4)]), "catmull_rom")
    t = np.linspace(0, 3, 31)
    assert np.allclose(line.positions_at(t)[:, 0], 2.0 * t)


def test_loop_repeats_and_is_smooth_across_the_seam():
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1], [0, 0, 0]], dtype=float)
    m = KeyframedMotion(np.arange(5.0), square, "catmull_rom", loop=True)
    t = np.linspace(-3, 3, 13)
    assert np.allclose(m.positions_at(t), m.positions_at(t + 4.0))
    h = 1e-6
    left = (m.positions_at(np.array([4.0])) - m.positions_at(np.array([4.0 - h]))) / h
    right = (m.positions_at(np.array([h])) - m.positions_at(np.array([0.0]))) / h
    assert np.allclose(left, right, atol=1e-4)


def test_waypoints_get_times_from_arc_length(tmp_path):
    doc = tiny(targets=[motion(waypoints=[[0, 0, 0], [3, 0, 0], [3, 0, 4]], speed_m_s=2.0, start_s=0.5)])
    m = load_scenario(write(tmp_path, doc)).targets[0].motion
    assert np.allclose(m.times, [0.5, 2.0, 4.0])


def _yaw_deg(q):
    forward = Rotation.from_quat(q).apply([0.0, 0.0, 1.0])
    return np.degrees(np.arctan2(forward[..., 0], forward[..., 2]))


def test_orientation_tracks():
    keys = np.array([[0.0, 0, 0, 0], [1.0, 0, 0, 0]])
    yaw = KeyframedMotion(keys[:, 0], keys[:, 1:], yaw_keys=np.array([[0.0, 0.0], [1.0, np.pi / 2]]))
    assert _yaw_deg(yaw.rotations_at(np.array([0.5]), np.array([0, 0, 0, 1.0])))[0] == pytest.approx(45.0)
    q90 = Rotation.from_euler("x", 90, degrees=True).as_quat()
    slerp = KeyframedMotion(keys[:, 0], keys[:, 1:], rotation_keys=np.array([[0.0, 0, 0, 0, 1], [1.0, *q90]]))
    half = Rotation.from_quat(slerp.rotations_at(np.array([0.5]), np.array([0, 0, 0, 1.0]))[0])
    assert half.magnitude() == pytest.approx(math.radians(45))
    # faces +X while walking along +X, holds that heading while standing, then turns to +Z
    walk = KeyframedMotion(
        np.array([0.0, 1.0, 2.0, 3.0]), np.array([[0, 0, 0], [1, 0, 0], [1, 0, 0], [1, 0, 1.0]]), orient_path=True
    )
    yaws = _yaw_deg(walk.rotations_at(np.array([0.5, 1.5, 2.5]), np.array([0, 0, 0, 1.0])))
    assert np.allclose(yaws, [90.0, 90.0, 0.0], atol=1e-6)
    # no orientation track: the actor's own rotation
    still = KeyframedMotion(keys[:, 0], keys[:, 1:])
    base = Rotation.from_euler("y", 30, degrees=True).as_quat()
    assert np.allclose(still.rotations_at(np.array([0.3, 0.7]), base), [base, base])


def test_bounce_stays_in_its_region_at_constant_speed():
    m = BounceMotion(np.array([0.0, 1.0, 0.0]), np.array([3.0, 0.0, -4.0]), 2.0, (-1.0, 1.0), (-2.0, 2.0))
    t = np.linspace(2.0, 30.0, 2801)
    p = m.positions_at(t)
    assert p[:, 0].min() >= -1 and p[:, 0].max() <= 1 and p[:, 2].min() >= -2 and p[:, 2].max() <= 2
    assert np.allclose(p[:, 1], 1.0)
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / np.diff(t)
    assert np.median(speed) == pytest.approx(5.0)
    assert np.allclose(m.positions_at(np.array([0.0, 2.0])), [[0, 1, 0], [0, 1, 0]])


# --------------------------------------------------------------------------------------------
# generators, spawning and frames


SPAWN = {
    "kind": "spawn",
    "id_prefix": "cyl",
    "count": 70,
    "batch": 4,
    "start_s": 0.0,
    "end_s": 47.0,
    "region": {"x": [-20, 20], "z": [-20, 20]},
    "shape": {"cylinder": {"radius": 0.5, "height": 3}},
    "speed_m_s": [0.5, 2.0],
    "clear_of_targets_m": 3.0,
    "seed": 4,
}


def test_spawn_generator_spreads_batches_and_parks_objects_until_their_time():
    s = parse_scenario(tiny(duration_s=60, generators=[SPAWN]))
    cyl = s.objects
    assert len(cyl) == 70 and all(a.dynamic for a in cyl) and cyl[0].id == "cyl000"
    spawn_times = sorted({a.spawn_s for a in cyl})
    assert len(spawn_times) == 18 and spawn_times[0] == 0.0 and spawn_times[-1] == 47.0
    assert [a.spawn_s for a in cyl].count(47.0) == 2
    late = cyl[-1]
    pos, _ = late.transforms_at(np.array([46.9, 47.0, 48.0]))
    assert pos[0][1] == pytest.approx(1.5 + PARK_OFFSET_M[1])
    assert pos[1][1] == pytest.approx(1.5)  # lowest point on the ground
    target = s.targets[0].position
    for a in cyl:
        p = a.transforms_at(np.array([a.spawn_s]))[0][0]
        assert math.hypot(p[0] - target[0], p[2] - target[2]) >= 3.5 - 1e-9
    again = parse_scenario(tiny(duration_s=60, generators=[SPAWN]))
    assert all(np.allclose(a.motion.velocity, b.motion.velocity) for a, b in zip(cyl, again.objects))


def test_scatter_keeps_spacing_clearance_and_exclusions():
    walker = motion(waypoints=[[-10, 1, 0], [10, 1, 0]], speed_m_s=2.0)
    scatter = {
        "kind": "scatter",
        "id_prefix": "tree",
        "count": 60,
        "region": {"x": [-15, 15], "z": [-15, 15]},
        "parts": [
            {"shape": {"cylinder": {"radius": 0.3, "height": 6}}},
            {"shape": {"sphere": {"radius": 1.5}}, "offset": [0, 4, 0]},
        ],
        "scale": [0.8, 1.2],
        "min_spacing_m": 2.0,
        "clear_of_targets_m": 1.0,
        "exclude": [{"x": [5, 15], "z": [5, 15]}],
    }
    s = parse_scenario(tiny(duration_s=10, targets=[walker], generators=[scatter]))
    trunks = [a for a in s.objects if a.id.endswith(".0")]
    crowns = [a for a in s.objects if a.id.endswith(".1")]
    assert len(trunks) == len(crowns) == 60 and not any(a.dynamic for a in s.objects)
    xz = np.array([[a.position[0], a.position[2]] for a in trunks])
    gaps = np.linalg.norm(xz[:, None] - xz[None], axis=2) + np.eye(60) * 99
    assert gaps.min() >= 2.0
    scale = np.array([a.scale[0] for a in trunks])
    assert scale.min() >= 0.8 and scale.max() <= 1.2
    on_path = np.abs(xz[:, 0]) <= 10
    assert np.all(np.abs(xz[on_path, 1]) >= 1.0 + 0.3 * scale[on_path] - 0.01)  # path sampled every 0.1 m
    assert not np.any((xz[:, 0] >= 5) & (xz[:, 1] >= 5))
    # parts stand on the ground: the trunk's base at 0, the crown's lowest point 4 m up (scaled)
    for trunk, crown in zip(trunks, crowns):
        assert trunk.position[1] == pytest.approx(3.0 * trunk.scale[1])
        assert crown.position[1] - 1.5 * crown.scale[1] == pytest.approx(4.0 * crown.scale[1], abs=0.02)


def test_frames_carry_only_what_moved_packed():
    doc = tiny(
        duration_s=1.0,
        frame_rate_hz=10,
        generators=[dict(SPAWN, count=3, batch=1, start_s=0.25, end_s=0.45)],
        objects=[{"id": "idle", "shape": {"sphere": {"radius": 1}}, "dynamic": True, "position": [5, 1, 5]}],
    )
    doc["targets"][0]["motion"] = {"position_keys": [[0.0, 0, 1, 0], [0.5, 1, 1, 0]]}
    s = parse_scenario(doc)
    frames = list(s.frame_updates("sid"))
    assert [f.frame for f in frames] == list(range(1, 12))
    assert frames[3].time_s == pytest.approx(0.3)
    assert sorted(frames[0].packed_ids) == ["cyl000", "cyl001", "cyl002", "idle", "t"]
    assert len(frames[0].packed_transforms) == 50
    ids = [sorted(f.packed_ids) for f in frames]
    assert ids[3] == ["cyl000", "t"]  # 0.3 s: cyl000 appeared at 0.25 s (teleport from its park)
    assert ids[6] == ["cyl000", "cyl001", "cyl002"]  # 0.6 s: the target stopped at 0.5 s
    assert all("idle" not in i for i in ids[1:])
    values = np.array(frames[3].packed_transforms).reshape(-1, 10)
    target = values[list(frames[3].packed_ids).index("t")]
    assert np.allclose(target[:3], [0.6, 1, 0]) and np.allclose(target[3:7], [0, 0, 0, 1]) and np.allclose(target[7:], 1)
    request = s.create_session_request(timeline=s.timeline())
    cyl2 = next(o for o in request.objects if o.id == "cyl002")
    assert cyl2.dynamic and cyl2.transform.position.y < -900  # declared parked
