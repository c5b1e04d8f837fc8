"""The program a cast received, written as it comes (`camdirector cast qtv --program-out FILE`) and
read back as evaluation/match/measure.py's Program on the match file imported from the same demo
(`camdirector eval-match MATCH --program FILE`): issue 42's program measured afterwards on the
recorded demo of the same match.

The file is JSON lines, each written as it comes (a cast stopped any way leaves a file that
reads): first the header {"program_of": the source, "level", "director", "delay_s", "rate_hz",
"roster": [{"id", "name", "team", "team_name", ...}]}; then one line per program reply (neither
buffering nor stale): frame, time_s (the session's game time of its moment), source_time_s (the
feed's clock at that frame: for QTV the stream's demo time its players were sampled at,
qtv.QtvTracks), players ({id: feet [3] m} as that frame carried them), position [3] m, rotation
[4] xyzw camera-to-world, vertical_fov_deg, cut, shot_id, kind (ShotKind less SHOT_), subjects
(ids), replay_time_s (a REPLAY's: the session's game time of the moment it shows; else null),
compute_ms, flags (the reply's Diagnostics.flags: why the camera is where it is, which eval-match's
short_shots and nobody_runs name; a file written before they were kept has none); last, when the
cast ended by itself, {"end": {"frames": sent, "buffering": replies buffering}}. The candidates
are not kept (hours of a cast would weigh too much), so their measures come out empty.

Read against a match. A QTV stream's demo time is not the recorded demo's: MVD blocks carry
time deltas, and a stream begins where the match was when the client joined, anew at each
reconnect. So the program is cut into pieces where its source clock leaps against the session's
(by over PIECE_LEAP_S between two moments: a reconnect, a re-anchored stream clock) and each
piece is aligned on its own: its shift onto the match's clock is the one, among every row of the
match, at which the players' feet its frames carried lie nearest the match's (median distance
over ALIGN_MOMENTS moments spread over the piece, each the median over its players). A piece
whose best shift leaves them more than ALIGN_LIMIT_M apart is left out (counted); a program with
no piece within it is not of this match. Then each moment goes to the match row of its piece's
shifted source time, of the two about it the one its players' feet match (`_rows_of`: a stream's
clock can run half a row off the file's grid), and the program's clock is the match's (shot lengths in match seconds;
beside them, as they went on air: `on_air_lengths_s`, below); moments beyond the match's ends by
more than a row's step are left out (counted); two moments on one row (the cast's frames jitter
against the file's grid) keep the later, cutting if either cut, as eval-match keeps the replies
of one moment (and a moment older than the one before is left out). The match's kills before the program's first moment were not
its to show and are left out, as measure.py leaves out those after its last. The feet a live
moment carried are where measure.py stands its bodies and tells whose eyes its camera is in
(`Program.feet_world`): a player through a teleport can be a row apart from the others.

The shots as they went on air are timed by the session's clock instead (time_s: the cast's
monotonic clock on its 1 / rate_hz grid, live_session.py), each placed moment counted. The two
clocks part where the stream clock plays the match slower to absorb a late segment (up to 5%,
stream_clock.py's slew), leaps ahead after a catch-up burst, or holds the demo's first sample over
the first frames (a cast of the 2on2 began with four moments at one demo time: its first shot
2.03 s on air, 1.93 s of the match). A viewer sees the on-air length; the match's clock is the
one eval-match's other measures read.
"""

from __future__ import annotations

import dataclasses
import json
import math
import threading
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import camdirector_client as cd
from camdirector.bridges.gsi_tracks import Sample
from camdirector.evaluation.match.match_file import MatchRecording
from camdirector.evaluation.match.measure import Program

MOMENT_KEYS = {
    "frame",
    "time_s",
    "source_time_s",
    "players",
    "position",
    "rotation",
    "vertical_fov_deg",
    "cut",
    "shot_id",
    "subjects",
}
ALIGN_MOMENTS = 32  # program moments whose players' feet place the program on the match
ALIGN_LIMIT_M = 1.0  # feet further apart than this at the best shift: not the same match, m
FEET_EQUAL_M = 0.01  # two rows whose feet lie this near alike from a moment's: its time picks (feet carried to 1 mm), m
# the source clock leaping this far against the session's between two moments starts a new piece, aligned on its own
# (a reconnect's stream starts its demo time anew; within one, the stream clock moves 0.05 s a second at most), s
PIECE_LEAP_S = 0.5


class ProgramRecorder:
    """Writes the program file (module docstring) as a cast runs: opened at once (OSError where it
    cannot be), begin() with the header once the session is open, then sent() from the stream's
    sending thread and reply() from the one reading its replies; close() writes the end line."""

    def __init__(self, path: Path):
        self._file = open(path, "w", encoding="utf-8", buffering=1)  # line-buffered: each line lands whole
        self._lock = threading.Lock()
        self._sent: deque[tuple[int, float | None, dict]] = deque()  # (frame, source time, feet) not answered yet
        self.frames = self.buffering = self.moments = 0
        self._begun = False

    def begin(self, header: dict[str, Any]) -> None:
        self._write(header)
        self._begun = True

    def _write(self, line: dict[str, Any]) -> None:
        with self._lock:
            self._file.write(json.dumps(line) + "\n")

    def sent(self, frame: int, time_s: float, sample: Sample) -> None:
        feet = {pid: [round(float(v), 3) for v in xyz] for pid, xyz in zip(sample.ids, sample.positions_world)}
        self._sent.append((frame, sample.source_time_s, feet))
        self.frames += 1

    def reply(self, reply: cd.pb.CameraUpdate) -> None:
        if reply.buffering:
            self.buffering += 1
            return
        if reply.stale or not reply.HasField("pose"):
            return
        while self._sent and self._sent[0][0] < reply.frame:  # moments gone by are never answered again
            self._sent.popleft()
        _, source_s, feet = self._sent[0] if self._sent and self._sent[0][0] == reply.frame else (0, None, {})
        p, q = reply.pose.position, reply.pose.rotation
        self.moments += 1
        self._write(
            {
                "frame": reply.frame,
                "time_s": round(reply.time_s, 4),
                "source_time_s": None if source_s is None else round(source_s, 4),
                "players": feet,
                "position": [p.x, p.y, p.z],
                "rotation": [q.x, q.y, q.z, q.w],
                "vertical_fov_deg": reply.pose.vertical_fov_deg,
                "cut": reply.cut,
                "shot_id": reply.shot_id,
                "kind": cd.pb.ShotKind.Name(reply.shot.kind).removeprefix("SHOT_"),
                "subjects": list(reply.shot.subject_ids),
                "replay_time_s": round(reply.shot.replay_time_s, 4) if reply.shot.kind == cd.pb.SHOT_REPLAY else None,
                "compute_ms": round(reply.compute_ms, 3),
                "flags": list(reply.diagnostics.flags),
            }
        )

    def close(self) -> None:
        if self._begun:  # a cast that opened no session leaves an empty file
            self._write({"end": {"frames": self.frames, "buffering": self.buffering}})
        self._file.close()


@dataclass(frozen=True)
class RecordedProgram:
    """A program file read back: its header, its moments (dicts as written) and its end line
    (None where the cast did not end by itself)."""

    header: dict[str, Any]
    moments: list[dict[str, Any]]
    end: dict[str, Any] | None


def read_program(path: Path) -> RecordedProgram:
    """The program file at path; OSError, or ValueError saying what is wrong with it."""
    lines = [line for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]
    try:
        rows = [json.loads(line) for line in lines]
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not a program file (line {exc.lineno}: {exc.msg})") from None
    if not rows or not isinstance(rows[0], dict) or "program_of" not in rows[0]:
        raise ValueError(f"{path}: not a program file (`cast qtv --program-out` writes one)")
    end = rows[-1].get("end") if isinstance(rows[-1], dict) else None
    moments = rows[1 : len(rows) - (end is not None)]
    bad = next((k for k, m in enumerate(moments) if not isinstance(m, dict) or not MOMENT_KEYS <= set(m)), None)
    if bad is not None:
        raise ValueError(f"{path}: line {bad + 2} is no program moment")
    if not moments:
        raise ValueError(f"{path}: the program has no moment (was the cast shorter than its delay?)")
    return RecordedProgram(rows[0], moments, end)


@dataclass(frozen=True)
class ProgramOnMatch:
    """A recorded program on a match (module docstring): the program, compute_ms (n,) of its
    moments, the match cut to the program's span (its kills before the first moment left out),
    how many moments were left out (with no source time, in a piece not of the match, or beyond
    the match's ends), shift_s (the first placed piece's: the match's time at a source time of 0,
    s), align_m (the largest of the placed pieces' median distances, m, of the players' feet at
    their shifts), the shots' lengths on air, pieces (placed, of all: module docstring) and each
    moment's reply flags."""

    program: Program
    compute_ms: np.ndarray
    match: MatchRecording
    left_out: int
    shift_s: float
    align_m: float
    on_air_lengths_s: np.ndarray  # (k,) s: the complete shots on the session's clock (`on_air_lengths_s`)
    pieces: tuple[int, int] = (1, 1)
    # each program moment's reply flags (of one row's moments, the one kept); empty where the file carries none
    flags: list[tuple[str, ...]] = dataclasses.field(default_factory=list)


def on_air_lengths_s(moments: list[dict[str, Any]]) -> np.ndarray:
    """(k,) s: the lengths of the complete shots of moments (in the order sent) on the session's
    clock, from the first moment and each cut to the next cut (module docstring); the last, cut
    short by the program's end, left out (measure.py shot_lengths_s on the match's clock)."""
    starts = [m["time_s"] for k, m in enumerate(moments) if k == 0 or m["cut"]]
    return np.diff(np.array(starts, dtype=np.float64))


def pieces(moments: list[dict[str, Any]]) -> list[list[dict[str, Any]]]:
    """moments (each with a source time) cut where the source clock leaps (module docstring)."""
    offset = np.array([m["source_time_s"] - m["time_s"] for m in moments])
    starts = [0, *(np.flatnonzero(np.abs(np.diff(offset)) > PIECE_LEAP_S) + 1).tolist(), len(moments)]
    return [moments[a:b] for a, b in zip(starts, starts[1:])]


def align(moments: list[dict[str, Any]], match: MatchRecording) -> tuple[float, float]:
    """(shift_s, align_m) of moments with a source time (module docstring): the shift of their
    clock onto the match's, a whole number of the match's rows, and the median distance of the
    players' feet there."""
    column = match.player_index()
    picks = [moments[k] for k in np.linspace(0, len(moments) - 1, min(ALIGN_MOMENTS, len(moments))).round().astype(int)]
    rows = len(match.time_s)
    shifts = np.arange(-rows, rows)  # the match row of a source time of 0
    per_moment = np.full((len(picks), len(shifts)), np.inf)
    for k, moment in enumerate(picks):
        ids = [pid for pid in moment["players"] if pid in column]
        if not ids:
            continue
        at = shifts + int(np.rint(moment["source_time_s"] * match.rate_hz))
        ok = (at >= 0) & (at < rows)
        feet = match.positions_world[at[ok]][:, [column[pid] for pid in ids]]  # (s, p, 3)
        apart = np.linalg.norm(feet - np.array([moment["players"][pid] for pid in ids]), axis=2)
        per_moment[k, ok] = np.median(apart, axis=1)
    distance = np.median(per_moment, axis=0)
    best = int(np.argmin(distance))
    return float(shifts[best] / match.rate_hz + match.time_s[0]), float(distance[best])


def _rows_of(moments: list[dict[str, Any]], at_rows: np.ndarray, match: MatchRecording) -> np.ndarray:
    """(n,) int64 the match row of each moment, its shifted source time at_rows (n,) in rows: of the
    two rows about it, the one where the players' feet the moment carried lie nearest the match's
    (median over its players), the nearer in time where they lie as near. A cast's stream clock
    runs half a row off the file's grid (the 2on2's at k + 0.5 rows, its file's times to 0.1 ms),
    where rounding the time goes either way: 53 of a cast's 6,051 moments were measured one row
    from their players, one a pose stepped back to 2.3 m from p01 measured with p01 2.1 m off."""
    column = match.player_index()
    last = len(match.time_s) - 1
    rows = np.clip(np.rint(at_rows), 0, last).astype(np.int64)
    for k, (moment, at) in enumerate(zip(moments, at_rows.tolist())):
        ids = [pid for pid in moment["players"] if pid in column]
        pair = np.clip([math.floor(at), math.floor(at) + 1], 0, last)
        if not ids or pair[0] == pair[1]:
            continue
        feet = np.array([moment["players"][pid] for pid in ids])
        apart = np.median(np.linalg.norm(match.positions_world[pair][:, [column[pid] for pid in ids]] - feet, axis=2), axis=1)
        if abs(apart[0] - apart[1]) > FEET_EQUAL_M:
            rows[k] = pair[int(np.argmin(apart))]
    return rows


def _feet_of(moments: list[dict[str, Any]], match: MatchRecording) -> np.ndarray:
    """(n, P, 3) float64 the players' feet each moment carried, m, in the match's columns; NaN
    for a player it did not carry and for a REPLAY's moment (it shows another moment's world)."""
    column = match.player_index()
    feet = np.full((len(moments), len(column), 3), np.nan)
    for k, moment in enumerate(moments):
        if moment.get("replay_time_s") is None:
            for pid, at in moment["players"].items():
                if pid in column:
                    feet[k, column[pid]] = at
    return feet


def program_on_match(recorded: RecordedProgram, match: MatchRecording) -> ProgramOnMatch:
    """Places the recorded program on the match (module docstring). ValueError where the program
    names players the match does not have, or it is not of this match."""
    missing = sorted({pid for m in recorded.moments for pid in m["subjects"]} - set(match.player_index()))
    if missing:
        raise ValueError(f"the program shows players the match does not have: {', '.join(missing)}")
    timed = [m for m in recorded.moments if m["source_time_s"] is not None and m["players"]]
    if not timed:
        raise ValueError("no moment of the program says where the players were")
    aligned = [(piece, *align(piece, match)) for piece in pieces(timed)]
    fits = [(piece, shift_s, align_m) for piece, shift_s, align_m in aligned if align_m <= ALIGN_LIMIT_M]
    if not fits:
        best_m = min(align_m for _, _, align_m in aligned)
        raise ValueError(
            f"the program is not of this match: its players' feet are {best_m:.1f} m from the match's at best"
            f" (over {ALIGN_LIMIT_M:g} m)"
        )
    timed = [m for piece, _, _ in fits for m in piece]
    step_s = 1.0 / match.rate_hz
    at_s = np.concatenate([np.array([m["source_time_s"] for m in piece]) + shift_s for piece, shift_s, _ in fits])
    inside = (at_s >= match.time_s[0] - step_s) & (at_s <= match.time_s[-1] + step_s)
    placed = [m for m, ok in zip(timed, inside) if ok]
    row = _rows_of(placed, (at_s[inside] - match.time_s[0]) * match.rate_hz, match)
    kept: list[dict[str, Any]] = []
    rows: list[int] = []
    cuts: list[bool] = []
    for moment, r in zip(placed, row.tolist()):
        if rows and r == rows[-1]:  # the moments of one row: the last stays, cutting if any cut
            kept[-1], cuts[-1] = moment, cuts[-1] or bool(moment["cut"])
        elif not rows or r > rows[-1]:  # one older than the one before is left out
            kept.append(moment)
            rows.append(r)
            cuts.append(bool(moment["cut"]))
    index = np.array(rows, dtype=np.int64)
    # a REPLAY shows an earlier moment: the same offset from the session's clock to the match's row
    shown = [
        r if m.get("replay_time_s") is None else r + int(np.rint((m["replay_time_s"] - m["time_s"]) * match.rate_hz))
        for m, r in zip(kept, rows)
    ]
    program = Program(
        index=index,
        time_s=match.time_s[index],
        position=np.array([m["position"] for m in kept], dtype=np.float64),
        rotation=np.array([m["rotation"] for m in kept], dtype=np.float64),
        vertical_fov_deg=np.array([m["vertical_fov_deg"] for m in kept], dtype=np.float64),
        cut=np.array(cuts, dtype=bool),
        shot_id=np.array([m["shot_id"] for m in kept], dtype=np.int64),
        subjects=[tuple(m["subjects"]) for m in kept],
        overview=np.array([m.get("kind") == "OVERVIEW" for m in kept], dtype=bool),
        shown_index=np.clip(np.array(shown, dtype=np.int64), 0, len(match.time_s) - 1),
        replay=np.array([m.get("kind") == "REPLAY" for m in kept], dtype=bool),
        feet_world=_feet_of(kept, match),
    )
    first_s, last_s = float(program.time_s[0]), float(program.time_s[-1])
    cut_match = match.until(last_s)
    cut_match = dataclasses.replace(cut_match, events=[e for e in cut_match.events if e.time_s >= first_s])
    compute_ms = np.array([m.get("compute_ms", np.nan) for m in kept], dtype=np.float64)
    flags = [tuple(m["flags"]) for m in kept] if all("flags" in m for m in kept) else []
    return ProgramOnMatch(
        program,
        compute_ms,
        cut_match,
        len(recorded.moments) - len(placed),
        fits[0][1],
        max(align_m for _, _, align_m in fits),
        on_air_lengths_s(placed),
        (len(fits), len(aligned)),
        flags,
    )
