"""camdirector._native.SearchCore (native/src/search.rs, amap.rs), the compiled twin of
pipeline/toric/occlusion_search.py's OcclusionSearch.step, against the Python step, call by call.

Every search step of Python sessions (the demo scene's walker among its moving obstacles in each
search mode; two targets walking among moving walls in ANTICIPATION and RAYCAST) is repeated by
both on identical inputs: the torus, the particle, the A-map and its window (or ray casts), a
Scene moved where the session's objects were, the target sample points, the side, and a
generator in the session's state. A session's own choices are not compared frame by frame: the
search chooses among candidates so close that a difference of 1e-14 m in where it starts chooses
another (docs/frame_path.md), so two sessions part after their first such choice.

Per call, both draw the same random numbers (the generators end in the same state); they ask
the same queries in the same order (places within 1e-9 rad or m, risks and occluded shares
within 1e-9, a place off the allowed range read as inf); and, when every decision of the Python
step is further than 1e-9 from its threshold and from its runner-up (a tie of equal values
counts as decided when the compiled values tie too), they make the same choice: the same move,
place, particle and pose within 1e-9. Calls closer than that are counted (`pytest -s`) and few.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
from collections import Counter
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pytest

from camdirector import _native as native
from camdirector.demo.client import frame_updates, session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.geometry.camera import Lens
from camdirector.geometry.toric import Torus
from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.style import MAP_MODES, Style
from camdirector.pipeline.toric.anticipation_map import AnticipationMap
from camdirector.pipeline.toric.camera_motion import pose_on_torus
from camdirector.pipeline.toric.occlusion_search import OcclusionSearch, RaycastRisk, SearchResult, SearchSettings
from camdirector.pipeline.toric.rig import ToricRig
from camdirector.pipeline.toric.visibility import VisibilityEstimate
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker.table import SessionTable
from tests.service.wire_client import box_object, capsule_target

TOL = 1e-9  # radians for angles, metres for places, unit for risks, shares and quaternions
FRAMES = 600  # 10 s at 60 Hz per session
MAX_UNDECIDED_SHARE = 0.01  # calls whose Python decisions are within TOL of a tie


@dataclass
class Call:
    """One search step's inputs, as ToricRig._search_step had them."""

    torus: Torus
    dt_s: float
    time_s: float
    side: float
    level: bool
    points_world: npt.NDArray[np.float64]
    particle: tuple[float, float, npt.NDArray[np.float64], float, float | None]
    rng_state: dict
    amap: AnticipationMap | None  # a copy; None: ray casts (RAYCAST)
    dynamic: dict[str, RigidTransform]
    style: Style
    lens: Lens
    settings: SearchSettings


def _walls_scene() -> tuple[pb.CreateSessionRequest, list[pb.FrameUpdate]]:
    """Two targets walking side by side on a 5 m circle, four static pillars and six walls
    (2.5 x 2.5 x 0.3 m) circling at 2-9 m, each at its own speed and way round."""
    pillars = [box_object(f"pillar{i}", (7.0 * math.cos(i * 1.6), 1.5, 7.0 * math.sin(i * 1.6))) for i in range(4)]
    rates = [(2.5, 0.5), (4.0, -0.35), (6.0, 0.3), (3.0, -0.6), (8.0, 0.25), (9.0, -0.2)]  # (radius m, rad/s)
    walls = [box_object(f"wall{i}", (r, 1.25, 0.0), size=(2.5, 2.5, 0.3), dynamic=True) for i, (r, _) in enumerate(rates)]
    request = pb.CreateSessionRequest(
        objects=pillars + walls,
        targets=[capsule_target("a", (5.0, 0.9, 0.0)), capsule_target("b", (6.0, 0.9, 0.0))],
        seed=11,
    )

    def state(object_id: str, x: float, y: float, z: float, yaw: float) -> pb.ObjectState:
        rotation = pb.Quat(y=math.sin(yaw / 2), w=math.cos(yaw / 2))
        return pb.ObjectState(id=object_id, transform=pb.Transform(position=pb.Vec3(x=x, y=y, z=z), rotation=rotation))

    frames = []
    for k in range(1, FRAMES + 1):
        t = k / 60.0
        walk = 0.25 * t  # rad: 1.25 m/s on the 5 m circle
        states = [state(n, r * math.cos(walk), 0.9, r * math.sin(walk), -walk) for n, r in (("a", 5.0), ("b", 6.0))]
        for i, (r, w) in enumerate(rates):
            angle = i * 1.1 + w * t
            states.append(state(f"wall{i}", r * math.cos(angle), 1.25, r * math.sin(angle), -angle))
        frames.append(pb.FrameUpdate(session_id="s", frame=k, time_s=t, states=states))
    return request, frames


def _demo_scene() -> tuple[pb.CreateSessionRequest, list[pb.FrameUpdate]]:
    scene = build_demo_scene(seed=7, duration_s=FRAMES / 60.0 + 1.0)
    frames = list(frame_updates(scene, FRAMES))
    for f in frames:
        f.session_id = "s"
    return session_request(scene, Lens()), frames


def _recorded_calls(make: tuple[pb.CreateSessionRequest, list[pb.FrameUpdate]], mode: int) -> tuple[list[Call], native.Scene]:
    """Every search step of a Python session (`make`'s scene and frames, `mode`, Embree maps), and
    a Scene of the session's meshes."""
    request, frames = make
    request.style.visibility, request.style.map_backend = mode, pb.MAP_BACKEND_EMBREE
    calls: list[Call] = []
    python_step = ToricRig._search_step

    def recording(
        rig: ToricRig, torus: Torus, state: FrameState, points_world: npt.NDArray[np.float64], side: float, level: bool
    ) -> tuple[SearchResult, object]:
        search = rig.search
        assert search.theta is not None
        maps = rig.maps if rig.style.visibility in MAP_MODES else None
        particle = (search.theta, search.phi, search.velocity_world.copy(), search.shot_start_s, search._occluded_since_s)
        calls.append(
            Call(
                torus,
                state.dt_s,
                state.time_s,
                side,
                level,
                points_world.copy(),
                particle,
                copy.deepcopy(search.rng.bit_generator.state),
                None if maps is None else copy.deepcopy(maps.amap),
                {object_id: transform for object_id, (_, transform) in rig.dynamic.items()},
                rig.style,
                rig.lens,
                search.settings,
            )
        )
        return python_step(rig, torus, state, points_world, side, level)

    table = SessionTable(ServerSettings(checkpoint_store="off", frame_path="python"))  # the reference's steps
    table.create("s", request)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(ToricRig, "_search_step", recording)
        for frame in frames:
            table.frame(frame)
    rig = table.get("s").session.rig
    scene = native.Scene(rig.ray_scene.static_meshes_world)
    for object_id, (mesh, transform) in rig.dynamic.items():
        scene.add_dynamic(object_id, mesh, transform)
    table.close_all()
    return calls, scene


class _Recorded:
    """A risk field that records each query (theta (n,), phi (n,), risk (n,)) of the Python step."""

    def __init__(self, risk, queries: list) -> None:
        self.inner, self.queries = risk, queries

    def risk(self, theta: npt.NDArray[np.float64], phi: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        value = np.asarray(self.inner(theta, phi), dtype=np.float64)
        self.queries.append(("risk", np.array(theta, dtype=np.float64), np.array(phi, dtype=np.float64), value))
        return value


def _arguments(call: Call, scene: native.Scene, rng: np.random.Generator) -> tuple:
    """SearchCore.step's arguments before the A-map for `call`."""
    return call.torus, call.particle, call.dt_s, call.time_s, call.side, scene, call.points_world, rng


def _generator(state: dict) -> np.random.Generator:
    rng = np.random.default_rng()
    rng.bit_generator.state = state
    return rng


def _python_step(call: Call, scene: native.Scene) -> tuple[OcclusionSearch, SearchResult, object, list]:
    """The Python step on the call's inputs, its ray casts through `scene`; its queries in order."""
    queries: list = []
    # the Python VISIBILITY stage's occluded fraction, casting through the Scene (RayScene's twin)
    casts = VisibilityEstimate(scene, [], np.random.default_rng(0))

    def occluded(cameras_world: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        value = casts.occluded_fraction(cameras_world, call.points_world)
        queries.append(("occluded", np.array(cameras_world, dtype=np.float64), value))
        return value

    if call.amap is not None:
        amap = call.amap
        risk = _Recorded(lambda theta, phi: amap.lookup(theta, phi, outside=1.0), queries)  # OcclusionMaps.risk
    else:
        raycast = RaycastRisk(call.torus, lambda cameras: casts.occluded_fraction(cameras, call.points_world))
        risk = _Recorded(raycast.risk, queries)
    search = OcclusionSearch(call.settings, _generator(call.rng_state))
    search.theta, search.phi, velocity, search.shot_start_s, search._occluded_since_s = call.particle
    search.velocity_world = velocity.copy()
    style = call.style
    result = search.step(call.torus, call.dt_s, call.time_s, risk, occluded, call.side, style.max_speed_m_s, style.max_accel_m_s2)
    pose = pose_on_torus(call.torus, result.theta, result.phi, style, call.lens, call.level)
    return search, result, pose, queries


def _gap(values: npt.NDArray[np.float64], best: int) -> float:
    """How far the least of `values` (index best) is from every other, exact ties left out."""
    others = np.delete(values, best)
    distinct = np.abs(others[others != values[best]] - values[best])
    return float(distinct.min()) if len(distinct) else math.inf


def _decision_margin(queries: list, search: OcclusionSearch, torus: Torus) -> float:
    """The least distance of any decision of the Python step from its threshold or runner-up."""
    s = search.settings
    margins = [math.inf]
    coast_risk = None
    for kind, *query in queries:
        if kind == "risk":
            theta, phi, value = query
            if coast_risk is None:  # the coast's, asked first
                coast_risk = float(value[0])
                continue
            masked = np.where(search._outside(theta, phi, *search._theta_range(torus)), np.inf, value)
            best = int(np.argmin(masked))
            margins += [_gap(masked, best), abs(masked[best] - (coast_risk - s.improvement))]
    shares = [query[2] for query in queries if query[0] == "occluded"]
    if not shares:  # no time step: nothing decided
        return math.inf
    margins.append(abs(float(shares[0][0]) - s.stuck_occluded))  # the stuck rule
    if len(shares) >= 2:  # a cut was tried: its current share, then its candidates'
        current = float(shares[1][0])
        margins.append(abs(current - s.improvement))
        if len(shares) == 3:
            best = int(np.argmin(shares[2]))
            margins += [_gap(shares[2], best), abs(shares[2][best] - (current - s.improvement))]
    return min(margins)


def _compare_queries(compiled: list, python: list, search: OcclusionSearch, torus: Torus) -> None:
    assert [q[0] for q in compiled] == [q[0] for q in python]
    for got, want in zip(compiled, python):
        if want[0] == "occluded":
            np.testing.assert_allclose(got[1], want[1], rtol=0, atol=TOL)
            np.testing.assert_allclose(got[2], want[2], rtol=0, atol=TOL)
            continue
        _, theta, phi, value = want
        np.testing.assert_allclose(got[1], theta, rtol=0, atol=TOL)
        np.testing.assert_allclose(got[2], phi, rtol=0, atol=TOL)
        outside = search._outside(theta, phi, *search._theta_range(torus)) if len(theta) > 1 else np.zeros(1, bool)
        assert np.array_equal(np.isinf(got[3]), outside)  # off the allowed range: inf, not asked
        np.testing.assert_allclose(got[3][~outside], value[~outside], rtol=0, atol=TOL)
        masked = np.where(outside, np.inf, value)
        ties = masked == masked.min()
        if ties.sum() > 1:  # a tie the Python breaks by index: the compiled values tie too
            assert len(set(got[3][ties].tolist())) == 1


def _check_call(call: Call, scene: native.Scene) -> tuple[str, bool]:
    """Both steps on the call's inputs (module docstring); answers the Python's move and whether
    its decisions were clear of ties (the compiled choice compared)."""
    for object_id, transform in call.dynamic.items():
        scene.set_transform(object_id, transform)
    search, result, pose, python_queries = _python_step(call, scene)
    rng = _generator(call.rng_state)
    core = native.SearchCore(call.settings, call.style, call.lens)
    theta, phi, cut, strategy, risk, particle, compiled_pose, queries = core.step(
        *_arguments(call, scene, rng), call.amap, call.level, True
    )
    assert rng.bit_generator.state == search.rng.bit_generator.state  # the same draws
    if _decision_margin(python_queries, search, call.torus) <= TOL:
        return result.strategy, False
    _compare_queries(queries, python_queries, search, call.torus)
    assert (strategy, cut) == (result.strategy, result.cut)
    assert abs(theta - result.theta) <= TOL and abs(phi - result.phi) <= TOL
    assert abs(risk - result.risk) <= TOL or (math.isnan(risk) and math.isnan(result.risk))
    assert (particle[0], particle[1]) == (theta, phi)  # the particle is where the answer is
    np.testing.assert_allclose(particle[2], search.velocity_world, rtol=0, atol=TOL)
    assert (particle[3], particle[4]) == (search.shot_start_s, search._occluded_since_s)
    np.testing.assert_allclose(compiled_pose[0], pose.position_world, rtol=0, atol=TOL)
    np.testing.assert_allclose(compiled_pose[1], pose.rotation_xyzw, rtol=0, atol=TOL)
    assert compiled_pose[2] == pose.vertical_fov_deg
    return result.strategy, True


SESSIONS = {
    "demo-ANTICIPATION": (_demo_scene, pb.ANTICIPATION),
    "demo-NO_ANTICIPATION": (_demo_scene, pb.NO_ANTICIPATION),
    "demo-RAYCAST": (_demo_scene, pb.RAYCAST),
    "walls-ANTICIPATION": (_walls_scene, pb.ANTICIPATION),
    "walls-RAYCAST": (_walls_scene, pb.RAYCAST),
}


@functools.cache
def _session(name: str) -> tuple[list[Call], native.Scene, list[tuple[str, bool]]]:
    """A session's calls, its Scene, and each call checked: (the Python's move, whether compared)."""
    make, mode = SESSIONS[name]
    calls, scene = _recorded_calls(make(), mode)
    return calls, scene, [_check_call(call, scene) for call in calls]


@pytest.mark.parametrize("name", list(SESSIONS))
def test_every_search_step_of_a_session_agrees_call_by_call(name):
    calls, _, moves = _session(name)
    assert len(calls) == FRAMES
    compared = Counter(strategy for strategy, clear in moves if clear)
    undecided = sum(not clear for _, clear in moves)
    print(name, dict(compared), "undecided:", undecided)  # pytest -s: what the sessions exercised
    assert undecided <= MAX_UNDECIDED_SHARE * len(moves)
    assert compared["coast"] and compared["single_frame"]


@pytest.mark.parametrize("scene_name", ["demo", "walls"])
def test_each_scene_makes_a_cut_and_watches_the_stuck_rule(scene_name):
    names = [name for name in SESSIONS if name.startswith(scene_name)]
    compared = Counter(s for name in names for s, clear in _session(name)[2] if clear)
    assert compared["cut"], compared
    assert any(call.particle[4] is not None for name in names for call in _session(name)[0])  # stuck watched


def test_the_sessions_together_compare_every_move():
    # Together, not each scene: which moves a session makes follows the CPU's float kernels (on an
    # AVX-512 machine the walls' sessions made no look-ahead step where an AVX2 one made some).
    compared = Counter(s for name in SESSIONS for s, clear in _session(name)[2] if clear)
    assert all(compared[move] for move in ("coast", "single_frame", "look_ahead", "cut")), compared


def test_no_time_step_stays_and_draws_nothing():
    calls, scene, _ = _session("walls-ANTICIPATION")
    call = calls[len(calls) // 2]
    rng = _generator(call.rng_state)
    core = native.SearchCore(call.settings, call.style, call.lens)
    for dt_s in (0.0, -0.01):
        theta, phi, cut, strategy, risk, particle, _, queries = core.step(
            call.torus, call.particle, dt_s, call.time_s, call.side, scene, call.points_world, rng, call.amap, call.level, True
        )
        assert (theta, phi, cut, strategy, queries) == (call.particle[0], call.particle[1], False, "coast", [])
        assert math.isnan(risk) and particle[:2] == call.particle[:2]
    assert rng.bit_generator.state == call.rng_state


@pytest.mark.parametrize("name", ["demo-ANTICIPATION", "walls-ANTICIPATION"])
def test_a_map_mode_before_its_first_update_reads_every_place_as_occluded(name):
    """An A-map with no update yet (after a cut, until the refill): risk 1 everywhere, so the step
    coasts or cuts, as the Python one does."""
    calls, scene, _ = _session(name)
    for call in calls[:: len(calls) // 12]:
        assert call.amap is not None
        empty = AnticipationMap(call.amap.target_count, call.amap.settings, call.amap.mask, call.amap.bank)
        strategy, clear = _check_call(dataclasses.replace(call, amap=empty), scene)
        assert clear and strategy in ("coast", "cut")


@pytest.mark.parametrize("name", ["demo-ANTICIPATION", "walls-RAYCAST"])
def test_a_step_repeats_bit_for_bit(name):
    calls, scene, _ = _session(name)
    for call in calls[:: len(calls) // 20]:
        for object_id, transform in call.dynamic.items():
            scene.set_transform(object_id, transform)
        core = native.SearchCore(call.settings, call.style, call.lens)
        first, second = (
            core.step(*_arguments(call, scene, _generator(call.rng_state)), call.amap, call.level, True) for _ in range(2)
        )
        assert first[:5] == second[:5] or (math.isnan(first[4]) and first[:4] == second[:4])
        assert first[5][2].tobytes() == second[5][2].tobytes() and first[5][:2] + first[5][3:] == second[5][:2] + second[5][3:]
        assert all(a.tobytes() == b.tobytes() for a, b in zip(first[6][:2], second[6][:2]))
        for got, want in zip(first[7], second[7]):
            assert got[0] == want[0] and all(a.tobytes() == b.tobytes() for a, b in zip(got[1:], want[1:]))


def test_bad_inputs_are_refused():
    calls, scene, _ = _session("walls-ANTICIPATION")
    call = calls[0]
    core = native.SearchCore(call.settings, call.style, call.lens)

    def step(points_world=call.points_world, amap=call.amap, rng=None):
        rng = _generator(call.rng_state) if rng is None else rng
        core.step(call.torus, call.particle, call.dt_s, call.time_s, call.side, scene, points_world, rng, amap, call.level)

    with pytest.raises(ValueError, match="points_world is empty"):
        step(points_world=np.zeros((0, 3)))
    with pytest.raises(ValueError, match="points_world has NaN"):
        step(points_world=np.full((2, 3), np.nan))
    wrong = copy.deepcopy(call.amap)
    assert wrong is not None
    wrong.a_map = np.zeros((3, 3), dtype=np.float32)
    with pytest.raises(ValueError, match=r"a_map must be \(64, 64\)"):
        step(amap=wrong)
    with pytest.raises(AttributeError, match="bit_generator"):
        step(rng=object())
