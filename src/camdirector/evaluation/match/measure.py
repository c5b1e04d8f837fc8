"""Measurement of a match program, independent of the director that chose it (issue 12, item 5).

The program is what a RIG_MATCH session answered: one camera per program moment (the match frame
its reply names), showing that frame's world, or during a REPLAY the frame it replays (the reply's
`shot.replay_frame`): every measure of bodies below reads the frame the picture shows. Everything
here is measured from that camera against the level mesh and the players' bodies as the match file
has them, never from what the director says it shows; but a cast's live moment (its program file
carries the players' feet its stream sampled: `Program.feet_world`) stands each body on those
feet, turned as the frame has it: a cast samples the stream half a row off the file's grid, and a
player running at 10 m/s is 0.17 m from either row (1.5 m from the camera, a tenth of its height
on the screen), one through a teleport metres off:

- shown fraction, per program moment and player: the share of the player's body sample points
  (`SAMPLES_PER_PLAYER` points drawn uniformly over its capsule's surface, fixed for the run) that
  lie in the camera's frame (geometry/camera.py's `in_frame`: in front of the near plane, inside
  the frame's edges at the pose's field of view and the lens's aspect) and whose segment from the
  camera centre crosses no level geometry (Embree ray casts, geometry.raycast.RayScene). Players do
  not occlude each other, as in evaluation/toric/measure.py. A player is *shown* at >= `SHOWN_FRACTION`.
  A player whose body (its capsule) holds the camera shows none of it: its surface faces away from
  a camera inside (a renderer culls it), and no game draws the body whose eyes it looks through
  (a dead player's camera at its corpse's eye looked at its own body's inside, 0.5 of its points
  "shown" and 1.0 of the frame tall).
- kill coverage: the share of kills at whose moment (the first program moment at or after the
  kill's frame) both the attacker and the victim are shown (live: a moment of a replay covers no
  kill). Kill coverage *first person* also
  counts a kill whose moment the program shows from the attacker's eyes (the camera within
  `EYE_TOLERANCE_M` of its eye point, `EYE_HEIGHT_FRACTION` of its height above its feet: what a
  QuakeWorld spectator tracking the attacker sees) with the victim shown.
- in the eyes of: the player whose eye point the camera is at (within EYE_TOLERANCE_M), if any
  (on a cast's carried feet where it has them).
  A first-person program shows that player's view, not its body: the measures below count the
  player as shown at those moments.
- lead, per covered kill: how long the program had been on the same shot (no cut) with both shown
  at every moment, up to the kill, s.
- shots: a shot runs from a cut (or the first program moment) to the next cut. Its length is the
  time between the two cuts; the last shot, cut short by the end of the match, is left out of the
  lengths. Cuts per minute count the cuts after the first moment over the program's duration.
- jump cuts: a cut between two views of the same non-empty subject set (`CameraUpdate.shot.
  subject_ids`) whose directions from the two cameras to the subjects' centroid (their aim points
  at the cut's moment) differ by less than `JUMP_CUT_DEG` (issue 12's film rule, measured: the
  director's own grammar is not consulted). Overviews name no subjects and are never jump cuts;
  nor are cuts into or out of a replay (a cut in time).
- replays (issue 41): a replay is a run of program moments of REPLAY shots of the same subjects
  (or its pair and, before the kill, one of them alone: a kill cam's killer, a victim's view's
  victim) whose replayed frames go forward (a cut within it, through a wall, does not start
  another); it is *shown* when a kill it replays (of the first subject of its pair by the
  second, its frame among the replayed ones) has both players shown at the replay's moment of
  the kill, the one through whose eyes the picture is (either) counting as shown. A replay that
  reaches back over two kills of its pair replays each it shows so: on a 30 Hz program of the
  real 2on2, a replay of a pair's second kill (with room) began 2.4 s before it, at their first
  (without), and was counted for the first alone. A kill *leaves room* when no other kill
  follows it within `room_s` (the director's wait after a kill, the shortest replay and the next
  kill's lead: replay_after_s + the style's min_shot_s + lead_s of MatchSettings) and the program goes
  on that long; kills with room replayed: those of them with a replay shown. A live kill missed
  for a replay is a kill whose moment is a replay's (issue 41: none).
- visibility of the framed subjects: per program moment with subjects, the mean shown fraction of
  the players it names, the player in whose eyes the camera is counting 1 (its body is not in
  its picture: see shown fraction); averaged over those moments.
- program visibility: the same over *every* program moment, a moment that names nobody counting
  the shown fraction of its best-shown player (an overview of nobody counts 0), the player in
  whose eyes the camera is counting 1.
- shown height: per program moment and shown player (not the one in whose eyes the camera is),
  the height on screen of its body's sample points, as a share of the frame's height; the median
  over all of them says whether players are large enough to read; the same over the players the
  shot names says whether its subjects are; the same over the moments in no one's eyes says it of
  the director's own framing (a first-person view shows players as the game does). The tallest
  shown player per program moment (the moments in someone's eyes left out: a first-person view is
  the game's own picture) says whether
  one is pressed against the lens: the largest over the program, and the share of moments with
  one taller than `TALL_HEIGHT` (issue 41: none).
- nobody shown: the share of program moments at which no player is shown (nor is the camera in
  anyone's eyes), split by whether the moment's shot is an OVERVIEW (the reply's `shot.kind`: the
  only establishing view the directors have) or not (issue 41: at most 2% outside overviews).
- candidates showing their subjects: of the candidates offered beside the program moments (each
  as often as offered), those naming subjects, and how many of them show at least half of their
  subjects (shown as above, from the candidate's own pose at the match frame of the moment it
  was offered beside; issue 41: at least 95%).
- places: of the program's poses (one per program moment) and of the candidates' poses (every
  candidate offered beside a program moment, as many times as offered), how many lie outside the
  level (its mesh's bounding box) or inside solid (geometry/inside.py says how it decides), and
  how many there are; and how many moves of the program camera between two moments with no cut
  between them pass through level geometry (a sweep through a wall, where a cut belongs), and how
  many are faster than JUMP_SPEED_M_S (a jump no wall lies across: to a viewer a cut, which the
  program does not flag, so that the shots it splits are counted as one).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from camdirector.evaluation.match.match_file import MatchPlayer, MatchRecording
from camdirector.geometry.camera import CameraPose, Lens, in_frame, project_to_screen
from camdirector.geometry.inside import LevelInterior, Place
from camdirector.geometry.meshes import TriMesh, capsule
from camdirector.geometry.raycast import RayScene
from camdirector.geometry.transforms import quat_to_matrix
from camdirector.pipeline.toric.target_sampling import SurfaceSampler

SAMPLES_PER_PLAYER = 32  # body sample points per player (issue 12 brief: 16-32)
SHOWN_FRACTION = 0.5  # a player is shown with at least this share of its points seen (issue 12, item 5)
JUMP_CUT_DEG = 30.0  # a cut between views of the same subjects closer than this is a jump cut (issue 12)
AIM_HEIGHT_FRACTION = 0.6  # the aim point (chest) this far up a player: the simulator's chest_height_fraction
EYE_HEIGHT_FRACTION = 46.0 / 56.0  # a Quake player's eye (origin + 22 units) over its 56-unit height
EYE_TOLERANCE_M = 0.5  # a camera this near a player's eye point looks through its eyes, m
TALL_HEIGHT = 0.6  # a shown player taller than this share of the frame's height is pressed against the lens (issue 41)
# a program camera moving faster than this between two moments jumped: 2 m between two 30-Hz frames, the
# edit window's JUMP_M (a teleport, a respawn), and twice a rocket-jumping player's speed, m/s
JUMP_SPEED_M_S = 60.0


def player_mesh(player: MatchPlayer) -> TriMesh:
    """The player's body: a capsule of its height and radius standing on its origin (its feet,
    the match file's position), so one transform places it as the match file says."""
    body = capsule(player.radius_m, player.height_m)
    return TriMesh(body.vertices + [0.0, 0.5 * player.height_m, 0.0], body.faces)


def aim_offset(player: MatchPlayer) -> np.ndarray:
    """(3,) m: the player's aim point (chest) in its local frame."""
    return np.array([0.0, AIM_HEIGHT_FRACTION * player.height_m, 0.0])


@dataclass(eq=False)
class Program:
    """The program of one director: n program moments in increasing frame order.

    index: (n,) int64 match frame (row of the match file's arrays) of each moment; time_s (n,) s;
    position (n, 3) m camera centre; rotation (n, 4) xyzw camera-to-world; vertical_fov_deg (n,);
    cut (n,) bool; shot_id (n,) int64; subjects: n tuples of player ids (the reply's
    shot.subject_ids); overview (n,) bool: the moment's shot is an OVERVIEW (shot.kind);
    shown_index (n,) int64: the match frame whose world the picture shows (a REPLAY's replayed
    moment, shot.replay_frame; else index); replay (n,) bool: the moment's shot is a REPLAY;
    feet_world (n, P, 3) float64 m or None: the players' feet the moment's director saw, where a
    cast's program file carries them (NaN where it did not: a replay's moment, a player it lacks),
    where the moment's bodies stand (`feet_at`) and so whose eyes the camera is in (`in_eyes_of`);
    None: the match file's at index.
    """

    index: np.ndarray
    time_s: np.ndarray
    position: np.ndarray
    rotation: np.ndarray
    vertical_fov_deg: np.ndarray
    cut: np.ndarray
    shot_id: np.ndarray
    subjects: list[tuple[str, ...]]
    overview: np.ndarray
    shown_index: np.ndarray
    replay: np.ndarray
    feet_world: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.index)

    def pose(self, row: int) -> CameraPose:
        return CameraPose(self.position[row], self.rotation[row], float(self.vertical_fov_deg[row]))

    def feet_at(self, row: int) -> np.ndarray | None:
        """(P, 3) m the players' feet the moment at `row` carried (NaN: the match file's), or None."""
        return None if self.feet_world is None else self.feet_world[row]

    def digest(self) -> str:
        """SHA-256 (hex) of every moment's frame, pose, cut, replayed frame and subjects: two runs
        gave the same program, pose for pose, exactly when their digests are equal."""
        h = hashlib.sha256()
        arrays = (self.index, self.position, self.rotation, self.vertical_fov_deg, self.cut, self.shot_id, self.shown_index)
        for array in arrays:
            h.update(np.ascontiguousarray(array).tobytes())
        h.update("\n".join(",".join(s) for s in self.subjects).encode("utf-8"))
        return h.hexdigest()


class BodySampler:
    """Fixed sample points on every player's body, carried to the world at any match frame."""

    def __init__(self, match: MatchRecording, rng: np.random.Generator, count: int = SAMPLES_PER_PLAYER):
        self.match = match
        self.points_local = np.stack([SurfaceSampler(player_mesh(p)).sample(count, rng) for p in match.players])  # (P, S, 3)
        self.aims_local = np.stack([aim_offset(p) for p in match.players])  # (P, 3)
        self.radius_m = np.array([p.radius_m for p in match.players])  # (P,) each capsule's, for `holding`
        self.height_m = np.array([p.height_m for p in match.players])  # (P,)

    def points_world(self, index: int, feet_world: np.ndarray | None = None) -> np.ndarray:
        """(P, S, 3) m: every player's sample points at match frame `index`, standing on feet_world
        (P, 3) m where given and finite (Program.feet_at) rather than the frame's."""
        rotation = quat_to_matrix(self.match.rotations_xyzw[index])  # (P, 3, 3)
        return np.einsum("pij,psj->psi", rotation, self.points_local) + self._feet(index, feet_world)[:, None, :]

    def _feet(self, index: int, feet_world: np.ndarray | None) -> np.ndarray:
        return on_feet(self.match.positions_world[index], feet_world)

    def holding(self, index: int, point_world: np.ndarray, feet_world: np.ndarray | None = None) -> np.ndarray:
        """(P,) bool: whose body, at match frame `index` (standing on feet_world as points_world
        does), holds the point (3,) m: within its radius of its capsule's axis (player_mesh: from
        radius to height - radius above its feet)."""
        rotation = quat_to_matrix(self.match.rotations_xyzw[index])  # (P, 3, 3) local-to-world
        local = np.einsum("pji,pj->pi", rotation, point_world - self._feet(index, feet_world))  # (P, 3)
        radius = self.radius_m
        along = np.clip(local[:, 1], radius, np.maximum(radius, self.height_m - radius))
        return np.asarray(np.hypot(np.hypot(local[:, 0], local[:, 1] - along), local[:, 2]) < radius)

    def aims_world(self, index: int, players: list[int]) -> np.ndarray:
        """(k, 3) m: the aim points of the players (columns) at match frame `index`."""
        rotation = quat_to_matrix(self.match.rotations_xyzw[index, players])
        return np.einsum("pij,pj->pi", rotation, self.aims_local[players]) + self.match.positions_world[index, players]


def on_feet(file_feet: np.ndarray, carried: np.ndarray | None) -> np.ndarray:
    """(..., 3) m a new array of the feet to measure on: the carried ones (Program.feet_world, same
    shape) where given and finite, else the match file's."""
    return file_feet.copy() if carried is None else np.where(np.isfinite(carried), carried, file_feet)


def shown_fractions(pose: CameraPose, lens: Lens, points_world: np.ndarray, level: RayScene) -> np.ndarray:
    """(P,) the share of each player's points (P, S, 3) m in the frame of `pose` and unoccluded by
    the level. Only points in the frame are ray cast: most players are off screen most of the time."""
    n_players, n_samples = points_world.shape[:2]
    flat = points_world.reshape(-1, 3)
    seen = in_frame(pose, lens, flat)
    candidates = np.flatnonzero(seen)
    if len(candidates):
        seen[candidates] = ~level.occluded(pose.position_world, flat[candidates])
    return seen.reshape(n_players, n_samples).mean(axis=1)


def measure_shown(program: Program, bodies: BodySampler, lens: Lens, level: RayScene) -> np.ndarray:
    """(n, P) shown fraction of every player at every program moment (module docstring): none of
    a body that holds the camera."""
    rows = []
    for r in range(len(program)):
        index, feet = int(program.shown_index[r]), program.feet_at(r)
        shown = shown_fractions(program.pose(r), lens, bodies.points_world(index, feet), level)
        rows.append(np.where(bodies.holding(index, program.position[r], feet), 0.0, shown))
    return np.stack(rows).reshape(len(program), len(bodies.match.players))


@dataclass(frozen=True)
class KillCoverage:
    """kills: kills whose moment the program reaches; covered (kills,) bool; lead_s: per covered kill, s."""

    kills: int
    covered: np.ndarray
    lead_s: np.ndarray

    @property
    def coverage(self) -> float:
        return float(self.covered.mean()) if self.kills else float("nan")


def in_eyes_of(match: MatchRecording, program: Program) -> np.ndarray:
    """(n,) int64: the column of the player in whose eyes the camera is at each program moment
    (module docstring), -1 where none. Where the program carries the feet its director saw
    (`Program.feet_world`), at those: a stream sampled half a row off the match file's grid can
    show a player through a teleport a row before the others (a cast's first-person moment through
    p02's eyes measured as a camera 4.4 m from p02, and p03 2.5 m off 0.73 of the frame tall)."""
    heights = np.array([p.height_m for p in match.players])
    eyes = on_feet(match.positions_world[program.shown_index], program.feet_world)  # (n, P, 3) feet
    eyes[..., 1] += EYE_HEIGHT_FRACTION * heights
    distance = np.linalg.norm(eyes - program.position[:, None, :], axis=2)  # (n, P)
    nearest = distance.argmin(axis=1)
    return np.where(distance[np.arange(len(program)), nearest] <= EYE_TOLERANCE_M, nearest, -1)


def kill_coverage(match: MatchRecording, program: Program, shown: np.ndarray, eyes_of: np.ndarray | None = None) -> KillCoverage:
    """Coverage and lead of the match's kills (module docstring); shown (n, P) from measure_shown.
    With eyes_of (n,) from in_eyes_of, a moment in the attacker's eyes that shows the victim
    covers the kill too (kill coverage first person)."""
    column = match.player_index()
    covered, leads = [], []
    for event in _kills(match):
        row = int(np.searchsorted(program.index, np.searchsorted(match.time_s, event.time_s), side="left"))
        if row >= len(program):
            continue  # after the program's last moment
        pair = [column[event.actor_id], column[event.other_actor_id]]
        both_shown = shown[:, pair].min(axis=1) >= SHOWN_FRACTION  # (n,)
        if eyes_of is not None:
            both_shown |= (eyes_of == pair[0]) & (shown[:, pair[1]] >= SHOWN_FRACTION)
        both_shown &= ~program.replay  # a replay shows another moment: the live kill is missed
        ok = bool(both_shown[row])
        covered.append(ok)
        if ok:
            start = row
            while start > 0 and program.shot_id[start - 1] == program.shot_id[row] and both_shown[start - 1]:
                start -= 1
            leads.append(float(program.time_s[row] - program.time_s[start]))
    return KillCoverage(len(covered), np.array(covered, dtype=bool), np.array(leads, dtype=np.float64))


def _kills(match: MatchRecording) -> list:
    """The kills by one player of another (a suicide or a death by the world has no attacker to show)."""
    return [e for e in match.events if e.kind == "kill" and e.actor_id != e.other_actor_id]


def _one_of(a: tuple[str, ...], b: tuple[str, ...]) -> bool:
    """Whether two moments' subjects are of one replay: the same, or its pair and its killer alone."""
    return set(a) <= set(b) or set(b) <= set(a)


def replay_figures(
    match: MatchRecording, program: Program, shown: np.ndarray, room_s: float, eyes_of: np.ndarray | None = None
) -> dict[str, int]:
    """The program's replays (module docstring): replays, shown, kills_with_room,
    kills_with_room_replayed, live_kills_missed_for_replay; shown (n, P) from measure_shown.
    With eyes_of (n,) from in_eyes_of, a replay in the killer's eyes that shows the victim at the
    kill is shown too (as kill_coverage counts a live kill), and one in the victim's eyes that
    shows the killer: the kill seen from its other end."""
    column = match.player_index()
    before = np.arange(len(program)) - 1
    goes_on = (
        (before >= 0)
        & program.replay
        & program.replay[before]
        & (program.shown_index >= program.shown_index[before])
        & np.array([_one_of(a, b) for a, b in zip(program.subjects, program.subjects[-1:] + program.subjects[:-1])], dtype=bool)
    )
    starts = np.flatnonzero(program.replay & ~goes_on)  # each replay's first moment
    replayed: set[int] = set()  # kills (their order in _kills) a shown replay shows
    shown_replays = 0
    kills = _kills(match)
    frames = np.searchsorted(match.time_s, [e.time_s for e in kills])
    for start in starts.tolist():
        end = start + 1
        while end < len(program) and goes_on[end]:
            end += 1
        rows = np.arange(start, end)
        subjects = max((program.subjects[r] for r in rows.tolist()), key=len)  # the pair (its killer alone before the kill)
        shows: set[int] = set()  # the kills of its pair this replay shows
        for k, event in enumerate(kills):
            inside = (program.shown_index[rows] >= frames[k]).nonzero()[0]
            if subjects != (event.actor_id, event.other_actor_id) or not len(inside) or program.shown_index[start] > frames[k]:
                continue
            row = rows[inside[0]]
            killer, victim = column[event.actor_id], column[event.other_actor_id]
            # through one's eyes, that one counts as shown
            seen = [1.0 if eyes_of is not None and eyes_of[row] == p else shown[row, p] for p in (killer, victim)]
            if min(seen) >= SHOWN_FRACTION:
                shows.add(k)
        replayed |= shows
        shown_replays += bool(shows)
    end_s = program.time_s[-1] if len(program) else -np.inf
    all_kill_s = np.array([e.time_s for e in match.events if e.kind == "kill"])
    with_room = [
        k
        for k, event in enumerate(kills)
        if event.time_s + room_s <= end_s and not np.any((all_kill_s > event.time_s) & (all_kill_s <= event.time_s + room_s))
    ]
    kill_rows = np.searchsorted(program.index, frames, side="left")
    live = kill_rows[kill_rows < len(program)]
    return {
        "replays": len(starts),
        "shown": shown_replays,
        "kills_with_room": len(with_room),
        "kills_with_room_replayed": len(replayed & set(with_room)),
        "live_kills_missed_for_replay": int(program.replay[live].sum()),
    }


def shot_starts(program: Program) -> np.ndarray:
    """(k,) int64: the program moment each shot starts at (its first, and every cut)."""
    starts: np.ndarray = np.flatnonzero(program.cut | (np.arange(len(program)) == 0))
    return starts


def shot_lengths_s(program: Program) -> np.ndarray:
    """(k,) s: the lengths of the complete shots (the last one, cut short by the match's end, left out)."""
    return np.diff(program.time_s[shot_starts(program)])


def cuts_per_minute(program: Program) -> float:
    duration_s = float(program.time_s[-1] - program.time_s[0]) if len(program) else 0.0
    return 60.0 * int(program.cut[1:].sum()) / duration_s if duration_s > 0 else float("nan")


def jump_cuts(program: Program, bodies: BodySampler, threshold_deg: float = JUMP_CUT_DEG) -> int:
    """Cuts between two views of the same subjects less than threshold_deg apart (module docstring)."""
    column = bodies.match.player_index()
    count = 0
    for row in np.flatnonzero(program.cut[1:]) + 1:
        before, after = program.subjects[row - 1], program.subjects[row]
        if not after or set(before) != set(after) or program.replay[row - 1] or program.replay[row]:
            continue  # a cut into or out of a replay is a cut in time
        centroid = bodies.aims_world(int(program.index[row]), [column[p] for p in after]).mean(axis=0)
        a, b = centroid - program.position[row - 1], centroid - program.position[row]
        cosine = a @ b / max(np.linalg.norm(a) * np.linalg.norm(b), 1e-12)
        count += bool(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))) < threshold_deg)
    return count


def framed_visibility(program: Program, shown: np.ndarray, column: dict[str, int], eyes_of: np.ndarray) -> float:
    """Mean over the moments that name subjects of their subjects' mean shown fraction, the player
    in whose eyes the camera is counting 1 (module docstring); NaN if none."""
    seen = _eyes_seen(shown, eyes_of)
    values = [seen[r, [column[p] for p in subjects]].mean() for r, subjects in enumerate(program.subjects) if subjects]
    return float(np.mean(values)) if values else float("nan")


def program_visibility(program: Program, shown: np.ndarray, column: dict[str, int], eyes_of: np.ndarray) -> float:
    """Mean over every program moment of its program visibility (module docstring); NaN without moments."""
    seen = _eyes_seen(shown, eyes_of)
    values = [
        seen[r, [column[p] for p in subjects]].mean() if subjects else seen[r].max(initial=0.0)
        for r, subjects in enumerate(program.subjects)
    ]
    return float(np.mean(values)) if values else float("nan")


def _eyes_seen(shown: np.ndarray, eyes_of: np.ndarray) -> np.ndarray:
    """(n, P) shown (from measure_shown) with the player in whose eyes the camera is (eyes_of (n,),
    -1 where none) counted 1 at each moment: its view, not its body."""
    seen = shown.copy()
    rows = np.flatnonzero(eyes_of >= 0)
    seen[rows, eyes_of[rows]] = 1.0
    return seen


def shown_heights_per_moment(
    program: Program, bodies: BodySampler, lens: Lens, shown: np.ndarray, eyes_of: np.ndarray, subjects_only: bool = False
) -> list[np.ndarray]:
    """Per program moment, (k,) the on-screen heights, share of the frame's height, of its shown
    players but the one in whose eyes the camera is (module docstring); subjects_only: of the
    players the moment's shot names alone (on open levels the players shown in the background,
    far off, outnumber the shot's own)."""
    column = bodies.match.player_index()
    out = []
    for r in range(len(program)):
        named = {column[p] for p in program.subjects[r]}
        players = [p for p in np.flatnonzero(shown[r] >= SHOWN_FRACTION) if p != eyes_of[r] and (not subjects_only or p in named)]
        if not players:
            out.append(np.zeros(0))
            continue
        pose = program.pose(r)
        points = bodies.points_world(int(program.shown_index[r]), program.feet_at(r))[players]  # (k, S, 3)
        frame_lens = Lens(vertical_fov_deg=pose.vertical_fov_deg, aspect=lens.aspect)
        screen_y = np.clip(project_to_screen(pose, frame_lens, points.reshape(-1, 3))[:, 1], -1.0, 1.0)
        screen_y = screen_y.reshape(len(players), -1)
        out.append((np.nanmax(screen_y, axis=1) - np.nanmin(screen_y, axis=1)) / 2.0)  # [-1, 1] is the frame
    return out


def shown_heights(
    program: Program, bodies: BodySampler, lens: Lens, shown: np.ndarray, eyes_of: np.ndarray, subjects_only: bool = False
) -> np.ndarray:
    """(m,) the heights of shown_heights_per_moment, every moment's together."""
    return np.concatenate([np.zeros(0), *shown_heights_per_moment(program, bodies, lens, shown, eyes_of, subjects_only)])


def third_person_heights(per_moment: list[np.ndarray], eyes_of: np.ndarray) -> np.ndarray:
    """(m,) the shown heights (per_moment from shown_heights_per_moment) of the moments in no
    one's eyes, together: the director's own framing (module docstring)."""
    return np.concatenate([np.zeros(0), *(h for h, eyes in zip(per_moment, eyes_of) if eyes < 0)])


def tallest_shown(per_moment: list[np.ndarray], eyes_of: np.ndarray) -> dict[str, float | None]:
    """The largest shown height (per_moment from shown_heights_per_moment) over the moments not in
    anyone's eyes, None without any, and the share of those moments with a player taller than
    TALL_HEIGHT (module docstring)."""
    tallest = np.array([h.max(initial=0.0) for h, eyes in zip(per_moment, eyes_of) if eyes < 0])
    if not len(tallest):
        return {"max": None, "over_60pc": None}
    return {"max": float(tallest.max()), "over_60pc": float((tallest > TALL_HEIGHT).mean())}


def nobody_moments(shown: np.ndarray, eyes_of: np.ndarray) -> np.ndarray:
    """(n,) bool: the program moments showing nobody (module docstring), from shown (n, P) and
    eyes_of (n,) (in_eyes_of: a view through a player's eyes is that player's)."""
    nobody: np.ndarray = (shown.max(axis=1, initial=0.0) < SHOWN_FRACTION) & (eyes_of < 0)
    return nobody


def nobody_shown(program: Program, shown: np.ndarray, eyes_of: np.ndarray) -> dict[str, float]:
    """The shares of program moments showing nobody in an OVERVIEW and in another shot (module
    docstring); NaN without moments."""
    nobody = nobody_moments(shown, eyes_of)
    if not len(program):
        return {"overview": float("nan"), "other": float("nan")}
    return {"overview": float((nobody & program.overview).mean()), "other": float((nobody & ~program.overview).mean())}


@dataclass(eq=False)
class Offered:
    """The candidates offered beside the program moments, each as often as offered: c of them.

    index (c,) int64 match frame each shows (of the moment it was offered beside; a REPLAY
    candidate's, its kill's: shot.replay_frame); position (c, 3) m;
    rotation (c, 4) xyzw; vertical_fov_deg (c,); subjects: c tuples of player ids (the
    candidate's shot.subject_ids)."""

    index: np.ndarray
    position: np.ndarray
    rotation: np.ndarray
    vertical_fov_deg: np.ndarray
    subjects: list[tuple[str, ...]]


def candidates_showing_subjects(offered: Offered, bodies: BodySampler, lens: Lens, level: RayScene) -> dict[str, int]:
    """Of the candidates offered, how many name subjects and how many of those show at least half
    of them (module docstring). Only the subjects' points are cast: a candidate's shown fraction of
    the others does not matter here."""
    column = bodies.match.player_index()
    named = showing = 0
    for k, subjects in enumerate(offered.subjects):
        if not subjects:
            continue
        named += 1
        pose = CameraPose(offered.position[k], offered.rotation[k], float(offered.vertical_fov_deg[k]))
        points = bodies.points_world(int(offered.index[k]))[[column[p] for p in subjects]]
        seen = shown_fractions(pose, lens, points, level) >= SHOWN_FRACTION
        showing += bool(2 * int(seen.sum()) >= len(subjects))
    return {"offered": named, "showing_half": showing}


def places_count(interior: LevelInterior, positions_world: np.ndarray) -> dict[str, int]:
    """Of the camera positions (n, 3) m: how many are outside the level, how many inside solid,
    and n (module docstring)."""
    places = interior.places(positions_world) if len(positions_world) else np.zeros(0, dtype=np.int8)
    return {"outside": int((places == Place.OUTSIDE).sum()), "solid": int((places == Place.SOLID).sum()), "poses": len(places)}


def jumps_without_cut(program: Program) -> int:
    """Moves of the program camera from one moment to the next, with no cut at the next, faster
    than JUMP_SPEED_M_S (module docstring)."""
    moves = np.flatnonzero(~program.cut[1:]) + 1
    distance_m = np.linalg.norm(program.position[moves] - program.position[moves - 1], axis=1)
    dt_s = np.maximum(program.time_s[moves] - program.time_s[moves - 1], 1e-9)
    return int((distance_m > JUMP_SPEED_M_S * dt_s).sum())


def sweeps_through_walls(interior: LevelInterior, program: Program) -> int:
    """Moves of the program camera from one moment to the next, with no cut at the next, whose
    segment passes through level geometry (module docstring)."""
    moves = np.flatnonzero(~program.cut[1:]) + 1
    moves = moves[np.any(program.position[moves] != program.position[moves - 1], axis=1)]
    if not len(moves):
        return 0
    return int((interior.reach(program.position[moves - 1], program.position[moves]) < 1.0).sum())
