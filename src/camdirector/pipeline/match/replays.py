"""Instant replays (issue 41, item 4): within the broadcast delay, a kill shown again from another angle.

A REPLAY shot (ShotKind.REPLAY, its `ShotChoice.replay`) plays a kill's game moments from
`replay_pre_s` before it to `replay_post_s` after it (longer before it when that is shorter than
the style's `min_shot_s`; shorter before it, down to `min_shot_s` in all, where the live timeline
has no more room; longer before it, filling the room, where the live shot it would leave before
the next beat is under `min_shot_s`: on the real 2on2 such a shot was 2.3 s, and the beat's own
cut waited for it to be `min_shot_s` old), at the program's pace, while the program's own time goes on: the rig
steps its camera and measures its visibility at the replayed moment (rig.py), and the buffer keeps
`kept_past_s` of past for it (moments.py). Its camera is the killer's eyes (the kill cam of
games' own replays: first_person.py) where they show the victim at the kill and its next frame
(readable, chest in frame, `eyes_seen` of it seen) and stand past `jump_cut_deg` from the live
camera (a kill shown live through those eyes is replayed from elsewhere): an eye never meets a
wall, where a Toric replay in a corridor was cut within itself (on the real duel's first 3
minutes, 7 of its 26 shots under 2 s began or ended in a replay). Else it is a Toric DUEL of killer and victim,
placed for the kill (its moment, the next frame's, and with less weight its build-up) at the place
that sees them best among those that turn the view of the pair by `jump_cut_deg` from the live
camera at the kill (grammar.py: a replay from the same angle shows nothing new). It frames the
pair throughout where a place sees both with `min_visible` of their points over those moments;
where none does, as the live planned DUEL does (shots.py `PairWindow`): the pair from
`pair_before_s` before the kill to `pair_after_s` after it, the killer alone before (each moment
scored for whom it frames then; the victim is mostly still behind walls in the build-up: 6 of the
real duel's 11 kills with room had no place seeing both over it, 5 of them one seeing both at the
kill). The pair first, so that a kill some place sees throughout is replayed as before (the
reframe's move can cross walls: cuts within the replay). None that sees them with `min_visible`
either way: through the victim's eyes where they show the killer at the kill and its next frame
and stand past `jump_cut_deg` from the live camera (the kill seen from its other end, as a
broadcast shows "what the victim saw"; on the real 2on2, 4 of 5 kills with room left unreplayed
had been shown live through the killer's eyes in corridors where no place saw both). Its eye
stays at a living player's height past the death: QuakeWorld drops a corpse's view to the floor,
which in a replay reads as the camera falling. Else no replay (at `candidate_seen`, 0.5, the real
wipeout's replays showed nobody for a second of build-up and nobody-shown frames outside
overviews rose from 7.7% to 10.7%). A replay whose build-up holds a jump of killer or victim
through the level (a teleport: moments.py `jumps_s`), where every camera of the pair passes through
a wall (a cut within the replay: on the real 2on2 a killer's teleport 0.8 s before its kill cut
its replay into shots of 1.17 and 0.03 s), shows as many moments from just after the jump instead
(`_after_jumps`), so more after the kill; where those show the victim's respawn (a jump through
the level too), the pair window's camera, which frames the killer alone by then, comes before the
pair's throughout. On the
wire a replay names whom it frames at the replayed moment (rig.py), as a live DUEL's killer-alone
frames do.

Our director (planned.py, `DirectorReplays`) inserts one when its own live decision keeps the
shot or cuts at its discretion (not for a planned beat: that discretionary shot can wait until
after the replay), the shot is `min_shot_s` old, the kill is `replay_after_s` past (the live shot has held it
and followed the survivor a moment; a hold for a later event gives way, as that event's beat has
its cut after the replay), and the live timeline
has room: no event of priority >= `beat_min_priority` in the program time a replay of at least
`min_shot_s` covers plus the next beat's `lead_s`, all of it within the buffered future (so never
with no delay). It
replays the latest kill of the last `replay_within_s` (never an older one once another came),
once; a replay on air ends at its length, or at once should an event come within `min_lead_s`
(and a planning tick) of its end (a plan applied late): the next beat still gets its cut.
The rig offers the latest kill shown live and not yet replayed as a REPLAY candidate (a Toric
one: the monitors preview Toric cameras, and a take airs what its monitor showed), and a
human's take of a REPLAY of killer and victim replays their latest kill (takes.py). Every choice
here reads the buffer and the poses the rig gave, never a clock: the same inputs make the same
replays.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from camdirector.geometry.camera import CameraPose
from camdirector.pipeline.inputs import EventKind, GameEvent
from camdirector.pipeline.match.first_person import FirstPersonCamera, eyes_camera, shows_at
from camdirector.pipeline.match.frame import Replay, ShotChoice, ShotKind
from camdirector.pipeline.match.interest import event_priority
from camdirector.pipeline.match.moments import TIME_EPSILON_S, Moment, MomentBuffer
from camdirector.pipeline.match.program_shot import Shot, ShotCamera
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shot_builder import ShotBuilder
from camdirector.pipeline.match.shots import PairWindow, Place, ToricCamera, best_place

AFTER_KILL_S = 0.1  # the replay's camera is placed for the kill's moment and this long after it (the next frame), s
BUILD_UP_STEP_S = 1.0  # and for the build-up, a moment this often from the replay's first on (each costs a tick's
# share of place-search work), s
BUILD_UP_WEIGHT = 0.5  # with this weight each against 1 for the kill's (placed for the kill alone, the program camera,
# finding the killer behind a wall in the build-up, pulled in toward it and still stood close at the kill:
# on the real wipeout, 1 of 2 replays showed both at the kill)
PLACED_KEPT = 16  # replay places remembered (per kill and live angle: a candidate asks at every tick)


def replayed_moment(buffer: MomentBuffer, shot: Shot, time_s: float) -> Moment:
    """The moment a REPLAY shot on air shows at program time time_s, s (its frame nearest: replayed
    times fall on frame times, up to rounding)."""
    replay = shot.choice.replay
    assert replay is not None  # asked of a replay only
    return buffer.at(replay.replayed_s(shot.start_s, time_s) + TIME_EPSILON_S)


def is_replay(shot: Shot | None) -> bool:
    return shot is not None and shot.choice.replay is not None


class Replays:
    """The REPLAY shots of one session's players (target order): which kill, from which place
    (module docstring)."""

    def __init__(self, players: list[str], builder: ShotBuilder):
        self.players, self.builder = players, builder
        self.index = {p: i for i, p in enumerate(players)}
        # a place of the pair's DUEL camera, or an int: through that player's eyes (the killer's or the victim's)
        self._placed: dict[
            tuple[float, float, str, str, bytes, bool], tuple[tuple[int, int], Place | int, float, PairWindow | None] | None
        ] = {}

    @property
    def settings(self) -> MatchSettings:
        return self.builder.settings

    def pair(self, kill: GameEvent) -> tuple[int, int] | None:
        """(killer, victim) indices of a kill by one player of another, else None."""
        killer, victim = self.index.get(kill.actor_id), self.index.get(kill.other_actor_id)
        if kill.kind != EventKind.KILL or killer is None or victim is None or killer == victim:
            return None
        return killer, victim

    def kills(self, buffer: MomentBuffer, now_s: float) -> list[GameEvent]:
        """The kills (by one player of another) a replay can show at program time now_s, oldest
        first: within replay_within_s before it, their replay's first moment still buffered."""
        s = self.settings
        start_s = max(now_s - s.replay_within_s, buffer.oldest_s + s.replay_pre_s)
        return [e for e in buffer.events_between(start_s, now_s) if self.pair(e) is not None]

    def replay(self, kill: GameEvent, min_shot_s: float, room_s: float = math.inf, oldest_s: float = -math.inf) -> Replay:
        """The moments a replay of the kill shows: at least min_shot_s of them, at most room_s, s,
        when that is more; all of room_s where the live shot it leaves before the next beat would
        be under min_shot_s, from no earlier than oldest_s, s (module docstring)."""
        s = self.settings
        length_s = max(min(s.replay_length_s, room_s), min_shot_s)
        if room_s - length_s < min_shot_s:  # no live shot between it and the beat: a longer build-up
            length_s = max(length_s, min(room_s, kill.time_s + s.replay_post_s - oldest_s))
        return Replay(kill.time_s, kill.time_s + s.replay_post_s - length_s, kill.time_s + s.replay_post_s)

    def shot(
        self,
        kill: GameEvent,
        buffer: MomentBuffer,
        live_world: np.ndarray | None,
        start_s: float,
        reason: str,
        held: bool = False,
        room_s: float = math.inf,
        eyes: bool = True,
    ) -> Shot | None:
        """A REPLAY shot of the kill (room_s: at most that long, s), on air from start_s, s, its
        camera turned jump_cut_deg from the live camera's centre (3,) m at the kill (None: any
        place), through the killer's eyes where they show it (`eyes`: may be) and the style allows
        first person; None when no such place sees both (module docstring)."""
        pair = self.pair(kill)
        assert pair is not None  # a replay is of a kill of one player by another
        # from no earlier than replay_past_s before its start: the buffer drops what is older than
        # kept_past_s before the program's moment as the program goes on (oldest_s runs up to
        # COMPACT_AFTER frames older), and keeps the edit window's length more for a replay it
        # starts early; a replay reaching into the dropped moments showed the oldest kept one still,
        # a step every 32 frames
        oldest_s = max(buffer.oldest_s, start_s - self.settings.replay_past_s)
        replay = self._after_jumps(self.replay(kill, self.builder.style.min_shot_s, room_s, oldest_s), pair, buffer)
        placed = self._placed_for(kill, pair, replay, buffer, live_world, eyes)
        if placed is None:
            return None
        (a, b), place, score, window = placed
        names = tuple(self.players[i] for i in pair)
        camera: ShotCamera
        if isinstance(place, Place):
            camera = ToricCamera(ShotKind.DUEL, a, b, self.builder.style, self.builder.lens, place)
            camera.pair = window
        else:  # the kill cam, or the victim's view
            camera = self._eyes(place, a, replay.kill_time_s)
        eyes_id = "" if isinstance(place, Place) else self.players[place]
        if eyes_id:
            reason = f"{reason} through {eyes_id}'s eyes"
        choice = ShotChoice(names, ShotKind.REPLAY, f"{reason}: {names[0]} -> {names[1]}", held, replay, eyes_id=eyes_id)
        shot = Shot(choice, pair, camera, start_s)
        shot.hold_until_s, shot.scores = start_s + replay.length_s, {"place_visibility": score}
        if window is not None:
            shot.cover_times_s = [replay.kill_time_s]  # its pair window's event (the rig keeps a window to its shot's events)
        return shot

    def _placed_for(
        self,
        kill: GameEvent,
        pair: tuple[int, int],
        replay: Replay,
        buffer: MomentBuffer,
        live_world: np.ndarray | None,
        eyes: bool,
    ) -> tuple[tuple[int, int], Place | int, float, PairWindow | None] | None:
        """`_place` of the replay, remembered per kill, first moment, live angle and `eyes` (a
        candidate asks at every tick)."""
        key = (
            kill.time_s,
            replay.from_s,
            kill.actor_id,
            kill.other_actor_id,
            b"" if live_world is None else live_world.tobytes(),
            eyes,
        )
        if key not in self._placed:
            if len(self._placed) >= PLACED_KEPT:
                del self._placed[next(iter(self._placed))]  # the oldest asked
            self._placed[key] = self._place(pair, replay, buffer, live_world, eyes)
        return self._placed[key]

    def _jumps(self, players: tuple[int, ...], start_s: float, end_s: float, buffer: MomentBuffer) -> list[float]:
        """The players' jumps through the level in (start_s, end_s], s (MomentBuffer.jumps_s)."""
        return buffer.jumps_s(players, start_s, end_s, self.builder.visibility.ray_scene.occluded)

    def _after_jumps(self, replay: Replay, pair: tuple[int, int], buffer: MomentBuffer) -> Replay:
        """The replay's moments moved past the pair's jumps through the level before the kill
        (module docstring): as long, from just after the last such jump up to the kill's next
        frame, where that is AFTER_KILL_S or more before the kill, they hold no jump of the
        killer after it and are buffered; else as they were. The victim's respawn after the
        kill is `_place`'s to keep out of the picture."""
        jumps = self._jumps(pair, replay.from_s, replay.kill_time_s + AFTER_KILL_S, buffer)
        if not jumps:
            return replay
        start_s = jumps[-1] + TIME_EPSILON_S
        moved = Replay(replay.kill_time_s, start_s, start_s + replay.length_s)
        if start_s > replay.kill_time_s - AFTER_KILL_S or moved.until_s > buffer.horizon_s:
            return replay
        return replay if self._jumps(pair[:1], start_s, moved.until_s, buffer) else moved

    def _window(self, kept: int, kill_time_s: float) -> PairWindow:
        """When a replay of a kill at kill_time_s, s, frames its pair: as a planned DUEL live, around
        the kill only, its kept player (the killer; the victim in the victim's view) alone before
        it (module docstring)."""
        s = self.settings
        return PairWindow(kept, (kill_time_s,), s.pair_before_s, s.pair_after_s, s.reframe_s)

    def _place(
        self, pair: tuple[int, int], replay: Replay, buffer: MomentBuffer, live_world: np.ndarray | None, eyes: bool
    ) -> tuple[tuple[int, int], Place | int, float, PairWindow | None] | None:
        """Through the killer's eyes (its index for the place) where they show the victim at the
        kill from past the live angle; else which of the builder's DUEL cameras (its players A and
        B), its place, score and pair window (None: the pair throughout), seeing the pair best at
        the kill past the live angle; the killer alone before the kill only where no place sees
        the pair throughout with min_visible; else through the victim's eyes (its index) where
        they show the killer at the kill from past the live angle; None where none does (module
        docstring)."""
        s = self.settings
        kill_moment = buffer.at(replay.kill_time_s)
        after = buffer.at(replay.kill_time_s + AFTER_KILL_S)
        # placed for the usual build-up: a replay filling its room shows more of it, weighed no more
        build_up = np.arange(max(replay.from_s, replay.kill_time_s - s.replay_pre_s), replay.kill_time_s, BUILD_UP_STEP_S)
        cover = [*(buffer.at(t) for t in build_up), kill_moment, after]
        weights = [BUILD_UP_WEIGHT] * len(build_up) + [1.0, 1.0]

        def other_angle(positions_world: np.ndarray) -> np.ndarray:
            return self.builder.grammar.allows_cut(live_world, kill_moment.aims_world[list(pair)], positions_world)

        def through(player: int, other: int) -> tuple[tuple[int, int], int, float, PairWindow | None] | None:
            """Through the player's eyes where they show the other at the kill and its next frame
            from past the live angle."""
            camera = self._eyes(player, pair[0], replay.kill_time_s)
            if not other_angle(camera.pose(kill_moment).position_world[None])[0]:
                return None
            visibility, heights = self.builder.visibility, self.builder.body_heights_m
            shown = all(shows_at(camera, (other,), m, visibility, heights, s) for m in (kill_moment, after))
            return (pair, player, 1.0, camera.pair) if shown else None

        kill_cam = through(*pair) if eyes and s.first_person else None
        if kill_cam is not None:
            return kill_cam

        # a camera framing the pair throughout meets the victim's respawn where the replay shows it
        # (a jump through the level: a cut within the replay); a pair window's frames the killer
        # alone by then, and comes first there
        alone = self._window(pair[0], replay.kill_time_s)
        alone_s = replay.kill_time_s + s.pair_after_s + s.reframe_s
        windows: tuple[PairWindow | None, ...] = (None, alone)
        if self._jumps((pair[1],), alone_s, replay.until_s, buffer):
            windows = (alone, None)
        for window in windows:
            best: tuple[tuple[int, int], Place, float, PairWindow | None] | None = None
            for camera, places in self.builder.cameras(ShotKind.DUEL, pair, kill_moment, default=False):
                assert camera.b_index is not None  # a DUEL's camera frames two
                camera.pair = window
                place, score = best_place(camera, places, cover, pair, self.builder.visibility, other_angle, kill_moment, weights)
                if best is None or score > best[2]:
                    best = ((camera.a_index, camera.b_index), place, score, window)
            if best is not None and best[2] >= s.min_visible:
                return best
        return through(pair[1], pair[0]) if eyes and s.first_person else None  # no place: the victim's view

    def _eyes(self, player: int, killer: int, kill_time_s: float) -> FirstPersonCamera:
        """A replay's camera through the player's eyes, of a kill by `killer` at kill_time_s, s:
        naming the player alone in the build-up (the kill cam its killer, the victim's view its
        victim). The victim's eye stays at a living player's height past its death (QuakeWorld
        drops a corpse's view to the floor: in a replay, a fall of the camera)."""
        height_m = float(self.builder.body_heights_m[player])
        camera = eyes_camera(player, height_m, self.builder.lens, self.settings, self._window(player, kill_time_s))
        if player != killer:
            camera.corpse_eye_above_feet_m = camera.eye_above_feet_m
        return camera


class DirectorReplays:
    """When our director inserts a replay (module docstring); the live camera's centres it saw at
    its decisions, to tell the live angle at a kill."""

    def __init__(self, replays: Replays):
        self.replays = replays
        self.tried: deque[float] = deque(maxlen=PLACED_KEPT)  # kill times replayed or found without a place
        self._live: deque[tuple[float, np.ndarray]] = deque()  # (program time s, live camera centre (3,) m)

    def saw(self, moment: Moment, pose: CameraPose | None, current: Shot | None) -> None:
        """Remembers the live camera's centre at a decision (none during a replay), replay_past_s long."""
        if pose is not None and not is_replay(current):
            self._live.append((moment.time_s, pose.position_world))
        while self._live and self._live[0][0] < moment.time_s - self.replays.settings.replay_past_s:
            self._live.popleft()

    def live_at(self, time_s: float) -> np.ndarray | None:
        """The live camera's centre (3,) m seen nearest time_s, s; None when none was."""
        if not self._live:
            return None
        return min(self._live, key=lambda seen: abs(seen[0] - time_s))[1]

    def ends(self, moment: Moment, buffer: MomentBuffer, current: Shot) -> bool:
        """Whether the replay on air gives the program back now: at its length, or for an event
        within min_lead_s and a planning tick of its end (module docstring)."""
        s = self.replays.settings
        end_s = current.hold_until_s
        return (
            moment.time_s >= end_s - 1e-9 or self._next_beat_s(buffer, moment.time_s) <= end_s + s.min_lead_s + s.plan_interval_s
        )

    def _next_beat_s(self, buffer: MomentBuffer, now_s: float) -> float:
        """Time of the next event after now_s that gets a planned beat, s (inf: none buffered)."""
        s = self.replays.settings
        events = buffer.events_between(now_s, buffer.horizon_s)
        return next((e.time_s for e in events if event_priority(e, s) >= s.beat_min_priority), math.inf)

    def insert(self, moment: Moment, buffer: MomentBuffer, current: Shot | None, flags: list[str]) -> Shot | None:
        """A REPLAY to cut to now in place of holding the live shot, or None (module docstring)."""
        s, style = self.replays.settings, self.replays.builder.style
        now = moment.time_s
        # a hold for a later event (the pair of a duel is in every kill) gives way: that event's own cut has room after
        if current is None or is_replay(current) or now - current.start_s < style.min_shot_s:
            return None
        kill = next(reversed(self.replays.kills(buffer, now)), None)  # only the latest: an older one is old news
        if kill is None or now < kill.time_s + s.replay_after_s or kill.time_s in self.tried:
            return None
        room_s = self._next_beat_s(buffer, now) - s.lead_s - now
        if now + self.replays.replay(kill, style.min_shot_s).length_s + s.lead_s > buffer.horizon_s or room_s < style.min_shot_s:
            return None
        self.tried.append(kill.time_s)
        shot = self.replays.shot(kill, buffer, self.live_at(kill.time_s), now, "replay of the kill", room_s=room_s)
        if shot is None:
            flags.append("replay_no_place")
        return shot
