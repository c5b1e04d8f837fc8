"""A human's takes: a shot a person holds on the program over every director's choice until they
release it (TakeShot; the rig's `PlayerInputs`, pipeline/camera_rig.py).

A take names players and a kind (none: FOLLOW for one player, DUEL for two, GROUP for more,
OVERVIEW for none). Taken, it goes to air at the next frame: as its preview monitor showed it when
a candidate matches it (the candidate's own camera and place), else built anew. While held, a
Toric camera of it is re-placed for visibility (replacement.py). A take whose held subject dies
(at the program moment) falls back, still held: to the player who killed it, else the nearest
fight to where it died, else an overview; `shot.reason` says so.

A take of a REPLAY names killer and victim (either order) and replays their latest kill the buffer
still reaches (replays.py): as its candidate offered it when one does, else placed anew. It is
held while it plays and released at its end (the director takes the program back); with no such
kill, or no place that sees both, it is released at once (flag `take_replay_refused`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from camdirector.pipeline.match.frame import ShotChoice, ShotKind
from camdirector.pipeline.match.moments import Moment, MomentBuffer
from camdirector.pipeline.match.program_shot import CandidateShot, Shot
from camdirector.pipeline.match.replays import Replays
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shot_builder import ShotBuilder
from camdirector.pipeline.match.situations import Situations


class Takes:
    """The takes of one session's players (target order): the one held, and whether a take or a
    release waits for the next tick (module docstring)."""

    def __init__(
        self, players: list[str], settings: MatchSettings, builder: ShotBuilder, situations: Situations, replays: Replays
    ):
        self.players, self.settings, self.builder, self.situations = players, settings, builder, situations
        self.replays = replays
        self.index = {p: i for i, p in enumerate(players)}
        self.held: ShotChoice | None = None
        self.pending = False

    def take(self, subject_ids: list[str], kind: ShotKind | None, release: bool) -> ShotChoice | None:
        """Holds a human's shot from the next frame until released; returns it (None on release).
        Raises ValueError for an unknown or repeated player or a kind that does not fit the count."""
        if release:
            self.held, self.pending = None, True
            return None
        unknown = [s for s in subject_ids if s not in self.index]
        if unknown:
            raise ValueError(f"take: unknown player {unknown[0]!r}; the players are {', '.join(self.players)}")
        if len(set(subject_ids)) != len(subject_ids):
            raise ValueError("take: a player is named twice")
        n = len(subject_ids)
        if kind is None:
            kind = {0: ShotKind.OVERVIEW, 1: ShotKind.FOLLOW, 2: ShotKind.DUEL}.get(n, ShotKind.GROUP)
        fits = {
            ShotKind.FOLLOW: n == 1,
            ShotKind.DUEL: n == 2,
            ShotKind.GROUP: 2 <= n <= self.settings.max_group,
            ShotKind.OVERVIEW: True,
            ShotKind.REPLAY: n == 2,
        }[ShotKind(kind)]
        if not fits:
            raise ValueError(f"take: a {ShotKind(kind).name} shot cannot show {n} players")
        self.held = ShotChoice(tuple(subject_ids), ShotKind(kind), "take: a human's choice, held until released", held=True)
        self.pending = True
        return self.held

    def held_shot(
        self, moment: Moment, buffer: MomentBuffer, current: Shot | None, candidates: list[CandidateShot], flags: list[str]
    ) -> tuple[Shot | None, ShotChoice | None]:
        """The held take as a shot when it must be (re)built: just taken, or a held subject died;
        and the take held from now on (the fallback's, when one died; None: a replay is over)."""
        held = self.held
        assert held is not None  # asked only while a take is held
        if held.kind == ShotKind.REPLAY:
            return self._replay(held, moment, buffer, current, candidates, flags)
        subjects = tuple(self.index[s] for s in held.subject_ids)
        dead = [i for i in subjects if not moment.alive[i]]
        if not dead and not self.pending and current is not None and current.held:
            return None, held
        if dead:
            choice, subjects = self._fallback(moment, buffer, dead[0])
            choice = held = dataclasses.replace(choice, held=True)
            flags.append("take_fallback")
        else:
            choice = held
            previewed = self._previewed(choice, moment, candidates)
            if previewed is not None:
                return previewed, held
        shot, _ = self.builder.build(choice, subjects, moment, [moment], current, None, moment.time_s)
        if shot is None:  # no place of its kind frames them within the band (a live cast's take from the dashboard met one)
            reason = f"{choice.reason}; wide: no level place frames them"
            wide = dataclasses.replace(choice, kind=ShotKind.OVERVIEW, reason=reason)
            shot, _ = self.builder.build(wide, subjects, moment, [moment], current, None, moment.time_s)
            flags.append("take_wide")
        assert shot is not None  # an overview always has its pose
        shot.held = True
        return shot, held

    def _previewed(self, choice: ShotChoice, moment: Moment, candidates: list[CandidateShot]) -> Shot | None:
        """A take of a shot the candidates offer goes to air as its preview monitor showed it:
        the candidate's own camera and place, not a new search (a human took what they saw; the
        30-degree rule is theirs to judge). None when no candidate matches the take."""
        for candidate, camera, _ in candidates:
            if camera is None or candidate.kind != choice.kind or set(candidate.subject_ids) != set(choice.subject_ids):
                continue
            if choice.kind == ShotKind.DUEL:
                assert camera.b_index is not None  # a DUEL's camera frames two
                self.builder.grammar.remember_duel(self.players[camera.a_index], self.players[camera.b_index])
            shot = Shot(choice, tuple(self.index[s] for s in candidate.subject_ids), camera, moment.time_s)
            shot.held = True
            return shot
        return None

    def _replay(
        self,
        held: ShotChoice,
        moment: Moment,
        buffer: MomentBuffer,
        current: Shot | None,
        candidates: list[CandidateShot],
        flags: list[str],
    ) -> tuple[Shot | None, ShotChoice | None]:
        """A REPLAY take (module docstring): its shot when just taken, held while it plays, and
        None when it is over or refused."""
        now = moment.time_s
        if not self.pending:
            playing = current is not None and current.held and current.choice.replay is not None
            return None, held if playing and current is not None and now < current.hold_until_s else None
        pair = set(held.subject_ids)
        for candidate, camera, _ in candidates:
            if candidate.replay is not None and camera is not None and set(candidate.subject_ids) == pair:
                subjects = tuple(self.index[s] for s in candidate.subject_ids)
                previewed = Shot(
                    dataclasses.replace(candidate, held=True), subjects, camera, now, now + candidate.replay.length_s
                )
                previewed.held = True
                return previewed, held
        kill = next((k for k in reversed(self.replays.kills(buffer, now)) if {k.actor_id, k.other_actor_id} == pair), None)
        shot = None if kill is None else self.replays.shot(kill, buffer, None, now, "take: a human's replay", held=True)
        if shot is None:
            flags.append("take_replay_refused")
            return None, None
        shot.held = True
        return shot, held

    def _fallback(self, moment: Moment, buffer: MomentBuffer, dead: int) -> tuple[ShotChoice, tuple[int, ...]]:
        who = self.players[dead]
        killer = buffer.killed_by.get(who)
        if killer is not None and moment.alive[self.index[killer]]:
            return (
                ShotChoice(
                    (killer,), ShotKind.FOLLOW, f"take fallback: held player {who} died (killed by {killer}); following {killer}"
                ),
                (self.index[killer],),
            )
        place = moment.feet_world[dead]
        fights = [o for o in self.situations.options(moment, buffer) if o.kind == ShotKind.DUEL]
        if fights:
            nearest = min(fights, key=lambda o: float(np.linalg.norm(moment.feet_world[list(o.subjects)].mean(axis=0) - place)))
            names = tuple(self.players[i] for i in nearest.subjects)
            return (
                ShotChoice(
                    names, ShotKind.DUEL, f"take fallback: held player {who} died; the nearest fight, {names[0]} vs {names[1]}"
                ),
                nearest.subjects,
            )
        return ShotChoice((), ShotKind.OVERVIEW, f"take fallback: held player {who} died; no fight, overview"), ()
