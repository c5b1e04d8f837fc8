"""A recorded match as a RIG_MATCH session's input: the CreateSession fields and the FrameUpdates.

Shared by `camdirector eval-match` (evaluate.py) and `camdirector play-match`
(matches/playback.py). The players are capsule targets standing on their feet with their team, their
names as the game gave them (display_name, team_name: shown to people, the ids stay the ids) and a
chest-high aim point (measure.py's `player_mesh` and `aim_offset`), level_id = the match's level;
the frames are the match subsampled to a rate (every k-th row of the file), the events of the
skipped rows riding on the next sent one, as a game sending at that rate would announce them, and,
where the match recorded them, the players' scoreboard values (player_stats: all of them on the
first frame, then those that changed); then the delay's tail: the last row held for delay_s more
seconds so that the program reaches the match's end. Frame numbers are match row + 1.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

import camdirector_client as cd
from camdirector.evaluation.match.match_file import EVENT_KINDS, STAT_COLUMNS, MatchEvent, MatchRecording
from camdirector.evaluation.match.measure import aim_offset, player_mesh

EVENT_KIND_MSG = dict(zip(EVENT_KINDS, (cd.pb.EVENT_KILL, cd.pb.EVENT_DAMAGE, cd.pb.EVENT_OBJECTIVE, cd.pb.EVENT_CUSTOM)))


@dataclass(frozen=True)
class Feed:
    """What is sent: rows (k,) int64 match rows of the sent frames (the last repeated for the
    delay's tail), frames (k,) int64 their frame numbers, times_s (k,) s their game times."""

    rows: np.ndarray
    frames: np.ndarray
    times_s: np.ndarray

    @classmethod
    def of(cls, match: MatchRecording, rate_hz: float, delay_s: float) -> Feed:
        step = max(1, round(match.rate_hz / rate_hz))
        rows = np.arange(0, len(match.time_s), step, dtype=np.int64)
        dt_s = step / match.rate_hz
        tail = np.arange(1, math.ceil(delay_s / dt_s) + 2, dtype=np.int64)  # one more: the last moment is reached
        frames = np.concatenate([rows + 1, rows[-1] + 1 + tail * step])
        times_s = np.concatenate([match.time_s[rows], match.time_s[rows[-1]] + tail * dt_s])
        return cls(np.concatenate([rows, np.full(len(tail), rows[-1])]), frames, times_s)

    @property
    def rate_hz(self) -> float:
        return float(1.0 / np.median(np.diff(self.times_s))) if len(self.times_s) > 1 else float("nan")


def player_targets(match: MatchRecording, player_ids: list[str] | None = None) -> list[cd.pb.Target]:
    """The players (or those named) as targets at their first frame: capsule bodies on their feet."""
    targets = []
    for i, player in enumerate(match.players):
        if player_ids is not None and player.id not in player_ids:
            continue
        body = player_mesh(player)
        targets.append(
            cd.pb.Target(
                id=player.id,
                team=player.team,
                display_name=player.name,
                team_name=player.team_name,
                mesh=cd.mesh_from_arrays(body.vertices, body.faces),
                transform=cd.transform_msg(match.positions_world[0, i], match.rotations_xyzw[0, i]),
                aim_offset=cd.vec3(aim_offset(player)),
            )
        )
    return targets


def match_session_fields(match: MatchRecording, director: str, delay_s: float, seed: int) -> dict:
    """The CreateSessionRequest fields of the match's RIG_MATCH session directed by `director`
    (a registered name, pipeline/match/director_registry.py; the server refuses one it does not
    hold), as keywords of `Client.create_session`."""
    return {
        "targets": player_targets(match),
        "level_id": match.level,
        "delay_s": delay_s,
        "seed": seed,
        "style": cd.pb.Style(rig=cd.pb.RIG_MATCH, match_director_name=director),
    }


def event_msg(event: MatchEvent) -> cd.pb.GameEvent:
    """The wire contract's GameEvent of a match event."""
    return cd.pb.GameEvent(
        kind=EVENT_KIND_MSG[event.kind],
        actor_id=event.actor_id,
        other_actor_id=event.other_actor_id,
        priority=event.priority,
        time_s=event.time_s,
        label=event.label,
        position=cd.vec3(event.position_world),
    )


def player_stats(match: MatchRecording, row: int, columns: list[int], since_row: int | None) -> list[cd.pb.PlayerStats]:
    """The scoreboard values (match.stats, STAT_COLUMNS) at `row` of the players in `columns` whose
    values differ from those at `since_row`; every one of them when since_row is None."""
    assert match.stats is not None  # asked only of a match that recorded them
    values = match.stats[row, columns].astype(np.int64)
    values[:, STAT_COLUMNS.index("items")] &= 0xFFFFFFFF  # a bitmask kept in int32: the wire's uint32
    changed = (
        np.ones(len(columns), dtype=bool)
        if since_row is None
        else np.any(match.stats[row, columns] != match.stats[since_row, columns], axis=1)
    )
    return [
        cd.pb.PlayerStats(id=match.players[c].id, **dict(zip(STAT_COLUMNS, v)))
        for c, v, differs in zip(columns, values.tolist(), changed.tolist())
        if differs
    ]


def frame_updates(
    session: cd.Session, match: MatchRecording, feed: Feed, columns: list[int], events: bool
) -> Iterator[cd.pb.FrameUpdate]:
    """The feed's FrameUpdates for the players in `columns`, packed; with `events`, each match
    event on the first sent frame at or after its own (events_per_frame) and, where the match has
    stats, the players' values on the first frame and on each frame where they changed."""
    per_frame = match.events_per_frame()
    ids = [match.players[c].id for c in columns]
    sent_through = -1
    for row, frame, time_s in zip(feed.rows.tolist(), feed.frames.tolist(), feed.times_s.tolist()):
        update = session.frame_update(
            frame, time_s, packed=cd.pack_states(ids, match.positions_world[row, columns], match.rotations_xyzw[row, columns])
        )
        if events:
            for r in range(sent_through + 1, row + 1):
                update.events.extend(event_msg(e) for e in per_frame[r])
            if match.stats is not None:
                update.player_stats.extend(player_stats(match, row, columns, None if sent_through < 0 else sent_through))
        sent_through = max(sent_through, row)
        yield update
