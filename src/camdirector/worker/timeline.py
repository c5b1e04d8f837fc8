"""A session's recent frames, for the dashboard: where the camera and the targets were, cuts and
shots, visibility, the framing error, and why the camera moved (the frame's flags: `search_cut`,
`pulled_in`, `tracks_cut_occlusion`, ...; the TRACKS rig's scores of the target it chose).

A bounded ring of plain values kept by the session table beside each session (in the worker that
holds it) and fed by the frame it has just answered; `GET /v1/sessions/{id}` reads it through the
worker's "timeline" operation. Stale frames are not added: they repeat the pose.

A MATCH session's frames also carry its rig's part of the frame (`FrameState.match`): the
program's shot, the candidate shots (each with its camera), the players (ids and teams, in target
order: `targets` are their aim points), the game events at the program moment (a viewer keeps its
own event log from them) and the director's planned next cut. While its broadcast delay fills, a
MATCH session answers `buffering` frames with no camera, numbered as the input frames; the
program's first frame replaces them (its frame numbers restart at the game's first moment), so
frame numbers still only grow within the ring.
"""

from __future__ import annotations

import math
from collections import deque
from typing import NamedTuple

import numpy as np
import orjson

from camdirector.geometry.transforms import quat_to_matrix
from camdirector.pipeline.inputs import EventKind
from camdirector.pipeline.match.frame import MatchFrame, ReplayedMoment, ShotChoice, ShotKind
from camdirector.pipeline.state import FrameState

TIMELINE_FRAMES = 600  # frames kept per session: 10 s at 60 Hz


class TimelineFrame(NamedTuple):
    """One answered frame, kept as computed (the JSON is made only when someone asks).
    camera_world: (3,) metres, None while buffering; rotation_xyzw: (4,) camera-to-world, None
    while buffering; targets_world: (k, 3) aim point per target; scores: the rig's own scoring of
    its choice (FrameState.scores' items, as (name, score) pairs); framing_error: the
    framed points from where the style puts them, normalised screen units (NaN: not measured);
    compute_ms: the server's time for the frame; match: the MATCH rig's part of the frame
    (`FrameState.match`, not copied: the rig makes it anew each frame), None for another rig.

    The ring holds each frame as a plain tuple of these fields, made a TimelineFrame when read. The
    collector stops tracking a plain tuple at its first pass when it holds only objects of types
    the collector never tracks (numbers, strings, numpy arrays) and such tuples; never a class's
    instance, nor a tuple holding a dict: hence the scores as pairs. A MATCH frame's part keeps its frame tracked.
    A worker holding 64 sessions kept 38,400 frames as instances, three quarters of its tracked
    objects, and its full collections took 13-25 ms, every frame waiting meanwhile."""

    frame: int
    time_s: float
    camera_world: np.ndarray | None
    rotation_xyzw: np.ndarray | None
    targets_world: np.ndarray
    cut: bool
    shot_id: int
    visibility: float
    framing_error: float
    flags: tuple[str, ...]
    scores: tuple[tuple[str, float], ...]
    compute_ms: float
    match: MatchFrame | None = None

    @property
    def buffering(self) -> bool:
        return self.match is not None and self.match.buffering


class Timeline:
    """The last `capacity` answered frames of one session, oldest first."""

    def __init__(self, capacity: int = TIMELINE_FRAMES) -> None:
        self._frames: deque[tuple] = deque(maxlen=capacity)  # TimelineFrame's fields (its docstring says why)

    def add(self, state: FrameState, compute_ms: float) -> None:
        """Costs a few microseconds a frame: copies, no conversion. A MATCH program frame drops
        the buffering frames before it (module docstring)."""
        pose, match = state.pose, state.match
        if match is not None and not match.buffering and self._frames and TimelineFrame._make(self._frames[-1]).buffering:
            self._frames.clear()
        self._frames.append(  # in TimelineFrame's order
            (
                int(state.frame),
                float(state.time_s),
                None if pose is None else pose.position_world.copy(),
                None if pose is None else pose.rotation_xyzw.copy(),
                np.array(state.aim_points_world),
                bool(state.cut),
                int(state.shot_id),
                float(state.visibility),
                state.framing_error,
                tuple(state.flags),
                tuple(state.scores.items()),
                float(compute_ms),
                match,
            )
        )

    def as_json(self, last: int | None = None, after_frame: int | None = None) -> list[dict]:
        """The newest `last` frames (all when None) of those after frame number `after_frame`
        (a live view asks only for what it has not seen), oldest first, for `dumps`: frame, time_s,
        camera, forward (unit; both null while buffering), targets, cut, shot_id, visibility,
        framing_error (null when not measured), flags, scores, compute_ms, and for MATCH
        (`_match_json`): buffering, shot, candidates, players, teams, events, planned_cut; vectors
        are numpy rows rounded to 0.1 mm. Built in bulk, since the worker that answers this also
        answers its sessions' frames (600 frames: about 2 ms with `dumps`, 18 ms as plain dicts and
        json)."""
        frames = list(map(TimelineFrame._make, self._frames))
        if after_frame is not None:
            first = len(frames)
            while first > 0 and frames[first - 1].frame > after_frame:  # frame numbers only grow
                first -= 1
            frames = frames[first:]
        frames = frames[-last:] if last else frames
        if not frames:
            return []
        cameras = [f.camera_world for f in frames if f.camera_world is not None]  # both None while buffering
        rotations = [f.rotation_xyzw for f in frames if f.rotation_xyzw is not None]
        camera = iter(np.stack(cameras).round(4) if cameras else ())
        forward = iter(_forward(rotations))
        targets = np.stack([f.targets_world for f in frames]).round(4)  # a session's targets are fixed
        rows = [
            {
                "frame": f.frame,
                "time_s": f.time_s,
                "camera": None if f.camera_world is None else next(camera),
                "forward": None if f.camera_world is None else next(forward),
                "targets": t,
                "cut": f.cut,
                "shot_id": f.shot_id,
                "visibility": round(f.visibility, 4),
                "framing_error": None if math.isnan(f.framing_error) else round(f.framing_error, 4),
                "flags": f.flags,
                "scores": dict(f.scores),
                "compute_ms": round(f.compute_ms, 3),
            }
            for f, t in zip(frames, targets)
        ]
        parts = [f.match for f in frames if f.match is not None]
        if parts:  # a session's rig is fixed: every frame has its MATCH part, or none has
            _match_json(parts, rows)
        return rows


def _forward(rotations_xyzw: list[np.ndarray]) -> np.ndarray:
    """(n, 3) unit view directions (the camera's -Z) of n (4,) camera-to-world quaternions, rounded."""
    if not rotations_xyzw:
        return np.zeros((0, 3))
    return (-quat_to_matrix(np.stack(rotations_xyzw))[:, :, 2]).round(4)


_SHOT_KINDS = {kind: f"SHOT_{kind.name}" for kind in ShotKind}  # as camdirector.v1 names them
_EVENT_KINDS = {kind: f"EVENT_{kind.name}" for kind in EventKind}


def _shot_json(shot: ShotChoice, replay_of: ReplayedMoment | None = None) -> dict:
    """A shot as the wire's ShotInfo; replay {frame, time_s, kill_time_s}: the moment a REPLAY's
    picture shows and its kill (null for a live shot)."""
    replay = (
        None
        if shot.replay is None
        else {
            "frame": None if replay_of is None else replay_of.frame,
            "time_s": None if replay_of is None else replay_of.time_s,
            "kill_time_s": shot.replay.kill_time_s,
        }
    )
    return {
        "subject_ids": shot.subject_ids,
        "kind": _SHOT_KINDS[shot.kind],
        "reason": shot.reason,
        "held": shot.held,
        "replay": replay,
        "eyes_id": shot.eyes_id,
    }


def _match_json(parts: list[MatchFrame], rows: list[dict]) -> None:
    """Adds the MATCH fields to each row (kinds named as in camdirector.v1: SHOT_DUEL, EVENT_KILL):
    shot {subject_ids, kind, reason, held, replay, eyes_id} or null; candidates [{shot, score, camera, forward}] (as the
    wire's CandidateShot); players (ids) and teams in target order; events [{time_s, kind,
    actor_id, other_actor_id, priority, label}]; planned_cut {time_s, shot} or null."""
    candidates = [c for m in parts for c in m.candidates]
    camera = iter(np.stack([c.pose.position_world for c in candidates]).round(4) if candidates else ())
    forward = iter(_forward([c.pose.rotation_xyzw for c in candidates]))
    roster, ids, teams = None, [], []
    for m, row in zip(parts, rows):
        if m.players is not roster:  # the rig shares one roster across frames: convert it once
            roster, ids, teams = m.players, [p for p, _ in m.players], [team for _, team in m.players]
        row.update(
            buffering=m.buffering,
            shot=None if m.shot is None else _shot_json(m.shot, m.replay_of),
            candidates=[
                {
                    "shot": _shot_json(c.shot, c.replay_of),
                    "score": round(c.score, 4),
                    "camera": next(camera),
                    "forward": next(forward),
                }
                for c in m.candidates
            ],
            players=ids,
            teams=teams,
            events=[
                {
                    "time_s": e.time_s,
                    "kind": _EVENT_KINDS[e.kind],
                    "actor_id": e.actor_id,
                    "other_actor_id": e.other_actor_id,
                    "priority": e.priority,
                    "label": e.label,
                }
                for e in m.events
            ],
            planned_cut=None
            if m.planned_cut is None
            else {"time_s": m.planned_cut.time_s, "shot": _shot_json(m.planned_cut.shot)},
        )


def dumps(value) -> bytes:
    """JSON bytes of a value holding `Timeline.as_json` frames (numpy rows and all)."""
    return orjson.dumps(value, option=orjson.OPT_SERIALIZE_NUMPY)
