"""Tiny hand-built matches for the MATCH rig's tests: box players on a floor, scripted motion and
events, driven frame by frame through a real Session (or a bare MatchRig with tuned settings)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from camdirector.geometry.camera import Lens, project_to_screen
from camdirector.geometry.meshes import TriMesh, box
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.inputs import EventKind, FrameInput, GameEvent, ObjectSpec, SceneSpec, TargetSpec
from camdirector.pipeline.match.rig import MatchRig
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.session import Session
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.style import Rig, Style

EYE_M = 1.6
RATE_HZ = 30.0
LENS = Lens()


def player_mesh() -> TriMesh:
    """A 0.5 x 1.8 x 0.5 m box standing on its local origin."""
    mesh = box((0.5, 1.8, 0.5))
    return TriMesh(mesh.vertices + np.array([0.0, 0.9, 0.0]), mesh.faces)


def yaw_quat(yaw_rad: float) -> np.ndarray:
    """xyzw rotation about +Y that turns local +Z to (sin yaw, 0, cos yaw)."""
    return np.array([0.0, math.sin(yaw_rad / 2.0), 0.0, math.cos(yaw_rad / 2.0)])


def facing(from_xz, to_xz) -> float:
    return math.atan2(to_xz[0] - from_xz[0], to_xz[1] - from_xz[1])


def kill(attacker: str, victim: str, time_s: float) -> GameEvent:
    return GameEvent(EventKind.KILL, attacker, victim, 0, time_s, "kill", None)


Script = Callable[[float], dict[str, tuple[tuple[float, float], float]]]  # t -> id -> ((x, z), yaw)


@dataclass
class Match:
    """Players (id -> team), a script of their places and facings, events, a delay and walls."""

    teams: dict[str, int]
    script: Script
    events: list[GameEvent] = field(default_factory=list)
    delay_s: float = 0.0
    walls: list[TriMesh] = field(default_factory=list)
    style: Style = field(default_factory=lambda: Style(rig=Rig.MATCH))
    seed: int = 7

    def scene(self) -> SceneSpec:
        start = self.script(0.0)
        targets = [
            TargetSpec(p, player_mesh(), _transform(*start[p]), np.array([0.0, EYE_M, 0.0]), team)
            for p, team in self.teams.items()
        ]
        objects = [ObjectSpec(f"wall{i}", w, RigidTransform(), False) for i, w in enumerate(self.walls)]
        return SceneSpec(objects, targets, LENS, self.style, self.seed, None, self.delay_s)

    def frames(self, duration_s: float):
        """FrameInputs at RATE_HZ; each event rides on the first frame at or after its time."""
        pending = sorted(self.events, key=lambda e: e.time_s)
        for k in range(int(duration_s * RATE_HZ) + 1):
            t = k / RATE_HZ
            places = self.script(t)
            due = [e for e in pending if e.time_s <= t + 1e-9]
            pending = pending[len(due) :]
            yield FrameInput("s", k, t, [(p, _transform(*places[p])) for p in self.teams], due)


def _transform(xz: tuple[float, float], yaw: float) -> RigidTransform:
    return RigidTransform(np.array([xz[0], 0.0, xz[1]]), yaw_quat(yaw))


def run_session(match: Match, duration_s: float, idle: bool = False) -> tuple[Session, list[FrameState]]:
    """Streams the match through a real Session; its answers in order. With `idle`, the session's
    deferred work is done between frames, a slice at a time until none is left (a worker's idle
    moments: camera_ahead.py's work ahead among it)."""
    session = Session("s", match.scene())
    states = []
    for update in match.frames(duration_s):
        states.append(session.frame(update))
        while idle and session.do_deferred_work(whole=False):
            pass
    return session, states


class BareRig:
    """A MatchRig with its own settings, fed as Session feeds it (for the tuned-rule tests)."""

    def __init__(self, match: Match, settings: MatchSettings):
        self.scene = match.scene()
        self.rig = MatchRig(self.scene, RayScene(match.walls), np.random.default_rng(match.seed), settings=settings)
        self.match = match

    def run(self, duration_s: float) -> list[FrameState]:
        states = []
        for update in self.match.frames(duration_s):
            transforms = [tf for _, tf in update.states]
            state = FrameState(update.frame, update.time_s, 0.0)
            state.aim_points_world = [tf.apply(t.aim_offset_local[None])[0] for tf, t in zip(transforms, self.scene.targets)]
            self.rig.run(state, update, transforms, states[-1] if states else None)
            states.append(state)
        return states


def at_time(states: list[FrameState], time_s: float) -> FrameState:
    """The answered state whose program moment is nearest time_s."""
    shown = [s for s in states if not s.match.buffering]
    return min(shown, key=lambda s: abs(s.time_s - time_s))


def on_screen(state: FrameState, points_world: np.ndarray) -> np.ndarray:
    """(n, 2) normalised screen positions of points from the state's pose."""
    return project_to_screen(state.pose, LENS, np.atleast_2d(points_world))


def shows(state: FrameState, ids: list[str], column: int) -> bool:
    """Whether the state's picture shows the player of that column: its aim point inside the frame
    of the pose (at the pose's own field of view), or the camera in its eyes (a first-person shot,
    first_person.py: the viewer sees what it sees)."""
    if state.match.shot.eyes_id == ids[column]:
        return True
    lens = Lens(state.pose.vertical_fov_deg, LENS.aspect)
    return bool(np.all(np.abs(project_to_screen(state.pose, lens, state.aim_points_world[column][None])) <= 1.0))


def shots(states: list[FrameState]) -> list[tuple[float, float, FrameState]]:
    """(start_s, end_s, first state) of each shot of the program, in order (the last one open-ended)."""
    shown = [s for s in states if not s.match.buffering]
    starts = [i for i, s in enumerate(shown) if s.cut or i == 0]
    out = []
    for a, b in zip(starts, starts[1:] + [len(shown)]):
        out.append((shown[a].time_s, shown[b - 1].time_s if b == len(shown) else shown[b].time_s, shown[a]))
    return out


def melee(
    seed: int,
    duration_s: float,
    delay_s: float,
    players_per_team: int = 5,
    kill_every_s: float = 3.3,
    respawn_s: float = 3.0,
    style: Style | None = None,
) -> Match:
    """Two teams circling in a 40 m square with four pillars; a kill of a random living opponent
    every kill_every_s; the victim lies still, then respawns (a jump to its other spawn) respawn_s
    later. Deterministic by seed."""
    rng = np.random.default_rng(seed)
    ids = [f"{side}{k}" for side in "ab" for k in range(players_per_team)]
    teams = {p: 1 if p[0] == "a" else 2 for p in ids}
    centre = {p: rng.uniform(-12.0, 12.0, 2) for p in ids}
    radius = {p: rng.uniform(2.0, 6.0) for p in ids}
    speed = {p: rng.uniform(0.3, 0.8) * rng.choice([-1.0, 1.0]) for p in ids}
    deaths: dict[str, list[float]] = {p: [] for p in ids}
    events = []
    t = 2.0
    while t < duration_s - 1.0:
        alive = [p for p in ids if not any(d <= t < d + respawn_s for d in deaths[p])]
        attacker = str(rng.choice(alive))
        victims = [p for p in alive if teams[p] != teams[attacker]]
        if victims:
            victim = str(rng.choice(victims))
            deaths[victim].append(t)
            events.append(kill(attacker, victim, round(t * RATE_HZ) / RATE_HZ))
        t += kill_every_s

    def place(p: str, time_s: float) -> tuple[tuple[float, float], float]:
        died = [d for d in deaths[p] if d <= time_s]
        if died and time_s < died[-1] + respawn_s:  # lying where it fell
            time_s = died[-1]
        respawns = sum(1 for d in deaths[p] if d + respawn_s <= time_s)
        c = centre[p] * (1.0 if respawns % 2 == 0 else -1.0)
        a = speed[p] * time_s
        x, z = c[0] + radius[p] * math.cos(a), c[1] + radius[p] * math.sin(a)
        yaw = math.atan2(-math.sin(a), math.cos(a)) if speed[p] > 0 else math.atan2(math.sin(a), -math.cos(a))
        foes = [q for q in ids if teams[q] != teams[p]]
        target = centre[foes[int(time_s / 4.0) % len(foes)]]
        if int(time_s) % 3 == 0:  # every third second, turn to face an opponent's area
            yaw = facing((x, z), target)
        return (float(x), float(z)), float(yaw)

    pillars = [
        TriMesh(box((2.0, 4.0, 2.0)).vertices + np.array([x, 2.0, z]), box((2.0, 4.0, 2.0)).faces)
        for x, z in ((-6.0, -6.0), (6.0, -6.0), (-6.0, 6.0), (6.0, 6.0))
    ]
    return Match(
        teams, lambda time_s: {p: place(p, time_s) for p in ids}, events, delay_s, pillars, style or Style(rig=Rig.MATCH), seed
    )
