"""The rig contract (pipeline/camera_rig.py): every rig provides every member of `CameraRig` with
the contract's parameters, a rig that does not override what only some rigs do gets `RigBase`'s
answers, the registry (pipeline/rigs.py) has one entry per rig and `make_rig` chooses through it,
and what only some rigs do answers as declared, on tiny scenes run through real sessions: two
capsules (TORIC), an actor in the corridor level (TRACKS, tests/precompute/tracks/tiny_levels.py),
two fronts of four players (MATCH, tests/pipeline/match/scenes.py)."""

from __future__ import annotations

import inspect
from dataclasses import replace

import numpy as np
import pytest

from camdirector.geometry.camera import CameraPose
from camdirector.geometry.meshes import capsule
from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline import rigs
from camdirector.pipeline.camera_rig import CameraRig, PlayerInputs, RigBase
from camdirector.pipeline.inputs import FrameInput, LoadedLevel, SceneSpec, TargetSpec
from camdirector.pipeline.match.frame import MatchFrame, ShotKind
from camdirector.pipeline.match.rig import MatchRig
from camdirector.pipeline.session import Session
from camdirector.pipeline.style import MapBackendChoice, Rig, Style, VisibilityMode
from camdirector.pipeline.toric.frame import ToricFrame
from camdirector.pipeline.toric.rig import ToricRig
from camdirector.pipeline.tracks.rig import TracksRig
from camdirector.precompute.tracks.pipeline import precompute_level
from camdirector.precompute.tracks.track_settings import TrackSettings
from tests.pipeline.match.scenes import LENS, RATE_HZ, Match, facing
from tests.precompute.tracks.tiny_levels import corridor
from tests.service.tracks_sessions import corridor_walk

RIGS = (ToricRig, TracksRig, MatchRig)  # the classes the registry's entries make, in its order
METHODS = ("run", "set_style", "close", "do_deferred_work", "anticipation_map")
PROPERTIES = ("has_deferred_work", "program_transforms", "player_inputs", "thread_bound")  # looked for on built rigs
OPTIONAL_METHODS = ("do_deferred_work", "anticipation_map")  # RigBase answers them


def members(protocol: type) -> set[str]:
    return {n for n in vars(protocol) if not n.startswith("_")} | set(protocol.__annotations__)


def parameters(function) -> list[tuple]:
    """(name, kind, default) of each parameter: what a caller relies on (annotations may narrow)."""
    return [(p.name, p.kind, p.default) for p in inspect.signature(function).parameters.values()]


def test_the_checks_below_cover_the_whole_contract():
    assert members(CameraRig) == {*METHODS, *PROPERTIES}
    assert members(PlayerInputs) == {"player_ids", "take"}


@pytest.mark.parametrize("name", METHODS)
@pytest.mark.parametrize("rig_class", RIGS)
def test_every_rig_has_each_method_with_the_contracts_parameters(rig_class, name):
    assert parameters(getattr(rig_class, name)) == parameters(getattr(CameraRig, name))


@pytest.mark.parametrize("rig_class", RIGS)
def test_every_rig_says_it_implements_the_contract_and_whether_it_has_deferred_work(rig_class):
    assert "implements `CameraRig`" in rig_class.__doc__
    member = inspect.getattr_static(rig_class, "has_deferred_work")
    assert isinstance(member, property) or member is False


class StillRig(RigBase):
    """A toy rig that implements `CameraRig` and overrides nothing optional: it holds one pose."""

    def __init__(self, scene: SceneSpec) -> None:
        self.lens = scene.lens

    def run(self, state, update, target_transforms, last) -> None:
        state.pose = CameraPose(np.array([0.0, 2.0, 6.0]), np.array([0.0, 0.0, 0.0, 1.0]), self.lens.vertical_fov_deg)

    def set_style(self, style: Style) -> None:
        pass

    def close(self) -> None:
        pass


@pytest.mark.parametrize("name", OPTIONAL_METHODS)
def test_the_base_answers_with_the_contracts_parameters(name):
    assert parameters(getattr(RigBase, name)) == parameters(getattr(CameraRig, name))


def test_a_rig_that_does_not_override_gets_the_defaults_and_one_entry_makes_it_a_sessions_rig(monkeypatch):
    entry = rigs.RigEntry(Rig.TORIC, "still", lambda scene, *session_parts: StillRig(scene), "holds one pose")
    monkeypatch.setattr(rigs, "_BY_RIG", {Rig.TORIC: entry})
    scene = SceneSpec([], [_target("a", (0.0, 0.9, 0.0))], LENS, Style(), seed=3)
    session = Session("s", scene)
    assert isinstance(session.rig, StillRig)
    state = session.frame(FrameInput("s", 1, 1 / 60.0, [("a", RigidTransform(np.array([0.0, 0.9, -0.02])))]))
    assert state.pose is not None and state.toric is None and state.match is None
    assert session.rig.anticipation_map(session.last_state) is None
    assert not session.rig.has_deferred_work and session.rig.do_deferred_work() is False
    assert session.rig.do_deferred_work(whole=False) is False
    assert session.rig.program_transforms is None and session.rig.player_inputs is None
    assert session.rig.thread_bound is False
    assert session.view_target_transforms() is session.target_transforms
    session.close()


def test_the_registry_has_one_entry_per_rig():
    assert [entry.rig for entry in rigs.RIGS] == list(Rig)
    assert len({entry.name for entry in rigs.RIGS}) == len(rigs.RIGS)
    for entry, rig_class in zip(rigs.RIGS, RIGS):
        assert entry.name == entry.rig.name.lower() and rig_class.__name__.lower() == f"{entry.name}rig"
        assert entry.description and "\n" not in entry.description


# -- the tiny scenes, each run through a real Session (INGEST, then the rig make_rig chose) --------


def _target(target_id: str, position_world, aim_m: float = 0.6, team: int = 0) -> TargetSpec:
    return TargetSpec(
        target_id, capsule(0.3, 1.8), RigidTransform(np.asarray(position_world, dtype=float)), np.array([0.0, aim_m, 0.0]), team
    )


def toric_session(mode: VisibilityMode, frames: int) -> tuple[Session, list]:
    """Two capsules 3 m apart, A walking away from B at 60 Hz."""
    scene = SceneSpec([], [_target("a", (0.0, 0.9, 0.0)), _target("b", (3.0, 0.9, 1.0))], LENS, Style(visibility=mode), seed=3)
    session = Session("s", scene)
    states = [
        session.frame(FrameInput("s", k, k / 60.0, [("a", RigidTransform(np.array([0.0, 0.9, -0.02 * k])))]))
        for k in range(1, frames + 1)
    ]
    return session, states


@pytest.fixture(scope="module")
def corridor_level() -> LoadedLevel:
    mesh = corridor()
    return LoadedLevel("corridor", precompute_level(mesh, TrackSettings(), np.random.default_rng(0)), mesh)


def tracks_session(level: LoadedLevel) -> tuple[Session, list]:
    """The actor walking the corridor for a second at 30 Hz."""
    times_s, feet_world = corridor_walk(1.0)
    scene = SceneSpec([], [_target("hero", feet_world[0], aim_m=1.6)], LENS, Style(rig=Rig.TRACKS), seed=1, level=level)
    session = Session("s", scene)
    states = [
        session.frame(FrameInput("s", k + 1, float(t), [("hero", RigidTransform(np.asarray(feet)))]))
        for k, (t, feet) in enumerate(zip(times_s, feet_world))
    ]
    return session, states


TEAMS = {"a1": 1, "b1": 2, "a2": 1, "b2": 2}


def two_fronts(t: float):
    return {
        "a1": ((0.0, 0.0), facing((0, 0), (0, 8))),
        "b1": ((0.0, 8.0), facing((0, 8), (0, 0))),
        "a2": ((40.0, 0.0), 0.0),
        "b2": ((40.0, 15.0), 0.0),
    }


# -- what only some rigs do, answered as declared ------------------------------------------------


def test_toric_draws_the_a_map_in_a_map_mode_and_defers_its_updates():
    session, states = toric_session(VisibilityMode.FRAMING_ONLY, 5)
    assert isinstance(session.rig, ToricRig)
    assert session.rig.anticipation_map(session.last_state) is None  # not a map mode
    assert not session.rig.has_deferred_work and session.rig.do_deferred_work() is False
    session, states = toric_session(VisibilityMode.ANTICIPATION, 60)
    a_map, (i, j) = session.rig.anticipation_map(session.last_state)
    n = session.style.map_resolution
    assert a_map.shape == (n, n) and np.nanmin(a_map) >= 0.0 and np.nanmax(a_map) <= 1.0
    assert -0.5 <= i <= n - 0.5 and -0.5 <= j <= n - 0.5  # the camera is on the window
    update = FrameInput("s", 61, 61 / 60.0, [])
    while not session.rig.has_deferred_work and update.frame < 180:  # an amortized map update, left for later
        session.frame(update)
        update = FrameInput("s", update.frame + 1, (update.frame + 1) / 60.0, [])
    assert session.rig.do_deferred_work() is True and not session.rig.has_deferred_work
    for state in states:
        assert isinstance(state.toric, ToricFrame) and state.match is None
    assert states[-1].toric.torus is not None
    assert session.rig.program_transforms is None and session.rig.player_inputs is None
    assert session.view_target_transforms() is session.target_transforms
    session.set_style(replace(session.style, map_backend=MapBackendChoice.EMBREE))
    assert session.rig.thread_bound is False  # Embree's scenes serve any thread
    session.set_style(replace(session.style, map_backend=MapBackendChoice.GL))
    assert session.rig.thread_bound is True  # GL's, in this thread's EGL context
    session.close()
    session.close()  # idempotent
    assert session.rig.anticipation_map(session.last_state) is None
    assert session.rig.thread_bound is False


def test_tracks_has_none_of_the_optional_capabilities(corridor_level):
    session, states = tracks_session(corridor_level)
    assert isinstance(session.rig, TracksRig)
    assert all(s.pose is not None for s in states) and any(s.scores for s in states)
    assert all(s.toric is None and s.match is None for s in states)  # all it answers is core
    assert session.rig.anticipation_map(session.last_state) is None
    assert not session.rig.has_deferred_work and session.rig.do_deferred_work() is False
    assert session.rig.program_transforms is None and session.rig.player_inputs is None
    assert session.rig.thread_bound is False
    assert session.view_target_transforms() is session.target_transforms
    session.close()


def test_match_takes_player_inputs_and_shows_a_delayed_program():
    match = Match(TEAMS, two_fronts, delay_s=0.5)
    session = Session("s", match.scene())
    assert isinstance(session.rig, MatchRig)
    frames = list(match.frames(2.0))
    buffering = [session.frame(update) for update in frames[: int(0.5 * RATE_HZ)]]
    assert all(isinstance(s.match, MatchFrame) and s.match.buffering and s.toric is None for s in buffering)
    assert session.rig.program_transforms is None  # the delay still fills: the latest frame's targets
    assert session.view_target_transforms() is session.target_transforms
    inputs = session.rig.player_inputs
    assert inputs is not None and inputs.player_ids == frozenset(TEAMS)
    taken = inputs.take(["a2"], None, release=False)
    assert (taken.subject_ids, taken.kind, taken.held) == (("a2",), ShotKind.FOLLOW, True)
    with pytest.raises(ValueError, match="unknown player"):
        inputs.take(["zz"], None, release=False)
    shown = [session.frame(update) for update in frames[int(0.5 * RATE_HZ) :]]
    assert all(not s.match.buffering and s.match.shot.subject_ids == ("a2",) for s in shown)
    program = session.rig.program_transforms
    assert len(program) == len(TEAMS) and session.view_target_transforms() is program
    assert session.rig.anticipation_map(session.last_state) is None
    assert session.rig.has_deferred_work  # the plan drawn at the last tick (held take: the fallback's check)
    assert session.rig.do_deferred_work() is True and not session.rig.has_deferred_work
    assert session.rig.do_deferred_work() is False
    assert inputs.take([], None, release=True) is None
    assert session.rig.thread_bound is False
    session.close()
