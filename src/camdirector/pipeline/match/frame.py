"""The MATCH rig's part of a frame's state (`FrameState.match`, pipeline/state.py), and what it
says about shots: whom a shot shows and how (`ShotChoice`, `ShotKind`), what a REPLAY shows again
(`Replay`, and the moment its picture shows, `ReplayedMoment`), the other shots the director could
cut to (`Candidate`), and its next planned cut (`PlannedCut`).

rig.py makes a new part every frame and shares only constant values between frames (the roster),
so a reader may keep a frame's part (the dashboard's timeline does) without copying it.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

from camdirector.geometry.camera import CameraPose
from camdirector.geometry.transforms import RigidTransform
from camdirector.pipeline.inputs import GameEvent


class ShotKind(enum.IntEnum):
    """What a shot shows (same numbers as camdirector.v1.ShotKind)."""

    DUEL = 1  # two opposing players, the Toric framing of both
    FOLLOW = 2  # one player
    GROUP = 3  # several players
    OVERVIEW = 4  # a high static view of the action
    REPLAY = 5  # a kill shown again from another angle, within the delay (replays.py)


@dataclass(frozen=True)
class Replay:
    """What a REPLAY shot shows again: the game moments from from_s to until_s around a kill at
    kill_time_s (game time, s), played at the program's pace from the shot's start."""

    kill_time_s: float
    from_s: float
    until_s: float

    @property
    def length_s(self) -> float:
        return self.until_s - self.from_s

    def replayed_s(self, shot_start_s: float, time_s: float) -> float:
        """The game time shown at program time time_s of a replay on air since shot_start_s, s: on
        past until_s, not frozen, should the cut back come a frame or two late (a plan applied
        late), and before from_s where the edit window starts the replay early (edit_window.py:
        its first moment held still there froze the picture for up to 0.8 s in casts of the 2on2)."""
        return self.from_s + (time_s - shot_start_s)


@dataclass(frozen=True)
class ShotChoice:
    """Whom a shot shows, how, and why (a human-readable reason)."""

    subject_ids: tuple[str, ...]
    kind: ShotKind
    reason: str
    held: bool = False  # a human's take (or its fallback), kept until released
    replay: Replay | None = None  # a REPLAY shot's kill and moments (None: live)
    eyes_id: str = ""  # the player through whose eyes the picture is (first_person.py); "": none


@dataclass(frozen=True)
class ReplayedMoment:
    """The game moment a REPLAY shot's picture shows: its frame number and time, s."""

    frame: int
    time_s: float


@dataclass(frozen=True)
class Candidate:
    """Another shot the director could cut to now, for a human director's preview monitors."""

    pose: CameraPose
    shot: ShotChoice
    score: float  # the director's interest in it, >= 0 (comparable within one frame)
    replay_of: ReplayedMoment | None = None  # a REPLAY candidate: the moment its monitor shows (its kill)
    transforms: list[RigidTransform] | None = None  # the players where its monitor shows them (its moment's)


@dataclass(frozen=True)
class PlannedCut:
    """The next cut the director has planned (with a delay, for an event it knows is coming)."""

    time_s: float  # program time of the cut, s
    shot: ShotChoice  # the shot it will cut to, with the reason


@dataclass
class MatchFrame:
    players: tuple[tuple[str, int], ...]  # (id, team) of each target in target order (the rig's roster)
    buffering: bool = False  # the broadcast delay is still filling: no pose, no shot
    shot: ShotChoice | None = None  # the program's shot (None while buffering)
    candidates: list[Candidate] = field(default_factory=list)  # the best other shots now
    events: list[GameEvent] = field(default_factory=list)  # the game events at the program moment
    planned_cut: PlannedCut | None = None  # the director's next planned cut, if it has one
    replay_of: ReplayedMoment | None = None  # during a REPLAY: the moment its picture shows (None: live)
