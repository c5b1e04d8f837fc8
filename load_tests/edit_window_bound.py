"""An offline bound for an edit window (issue 41, item 3: docs/casting.md, "Where the short shots
come from"): what the real matches' programs would measure if every shot under 2 s were given to
a neighbour, as a rig working `min_shot_s` ahead of the program it answers could (built since:
pipeline/match/edit_window.py; on its programs this bounds what is left of the short shots).

    python -m load_tests.edit_window_bound [--only 4on4_dm2,...] [--minutes 3] [--delay 10] [--json out.json]

Each match of load_tests.real_matches is streamed through our director (eval-match's own run,
unpaced, which gives the paced program), then each shot under SHORT_SHOT_S, in time order, is
given to the shot before it or to the one after, whichever shows its subjects (eval-match's
shown fraction) on more of those frames: through the same eyes where that shot was in a player's
eyes and the player does not jump there (its eye carried on), else that shot's last or first pose
held still. A held pose is worse than the moving camera a real window would carry on, so the
figures bound the design from below. A replay's piece goes only to a piece of the same replay
(its replayed frames go on), a live shot only to a live one (a cut into or out of a replay is a
cut in time).
Prints eval-match's figures before and after, per match.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from camdirector.evaluation.match.measure import SHOWN_FRACTION, Program, shot_starts
from load_tests.real_matches import MATCHES, prepare
from load_tests.report import emit

# (k, 3) positions m, (k, 4) rotations xyzw, (k,) vertical fov deg: the poses a neighbour gives k frames
Poses = tuple[np.ndarray, np.ndarray, np.ndarray]
# (program, the short shot's rows, the neighbour's row) -> (the share of the rows showing its subjects, its poses)
Judge = Callable[[Program, np.ndarray, int], tuple[float, Poses]]

REPLAY_GAP_FRAMES = 2  # a replay's pieces whose replayed frames are this close across a cut are one replay going on
JUMP_M = 2.0  # a player's feet moving this far between two frames jumped (teleport, respawn): no eye carried across it, m
FIGURES = (
    ("shots <2 s", lambda f: f["shots"]["under_2s"]),
    ("shot median s", lambda f: f["shots"]["median"]),
    ("kill coverage", lambda f: f["kill_coverage_first_person"]),
    ("program vis.", lambda f: f["program_visibility"]),
    ("nobody (other)", lambda f: f["nobody_shown"]["other"]),
    ("height median", lambda f: f["shown_height"]["median"]),
    (">60%", lambda f: f["shown_height"]["over_60pc"]),
)


def repaired(program: Program, judge: Judge, short_s: float) -> tuple[Program, dict[str, int]]:
    """A copy of `program` (evaluation/match/measure.py Program) with each shot under short_s, s,
    in time order, given to the shot before it (its cut removed) or the one after (the next cut
    removed), whichever `judge` says shows its subjects more (ties to the shot before), among
    the neighbours of its kind (`_donors`); the first shot and one with none are left. And the
    counts of each."""
    p = dataclasses.replace(
        program,
        position=program.position.copy(),
        rotation=program.rotation.copy(),
        vertical_fov_deg=program.vertical_fov_deg.copy(),
        cut=program.cut.copy(),
        subjects=list(program.subjects),
        overview=program.overview.copy(),
    )
    counts = {"to_the_shot_before": 0, "to_the_shot_after": 0, "left": 0}
    left: set[int] = set()
    while True:
        starts = shot_starts(p).tolist()
        short = [(a, b) for a, b in zip(starts, starts[1:]) if p.time_s[b] - p.time_s[a] < short_s - 1e-6 and a not in left]
        if not short:
            return p, counts
        a, b = short[0]
        rows = np.arange(a, b)
        donors = _donors(p, a, b)
        if not donors:
            left.add(a)
            counts["left"] += 1
            continue
        judged = [(judge(p, rows, d), d) for d in donors]
        (_, poses), donor = max(judged, key=lambda j: j[0][0])  # the first of equals: the shot before
        p.position[rows], p.rotation[rows], p.vertical_fov_deg[rows] = poses
        for r in rows:
            p.subjects[r] = p.subjects[donor]
        p.overview[rows] = p.overview[donor]
        p.cut[a if donor == a - 1 else b] = False
        counts["to_the_shot_before" if donor == a - 1 else "to_the_shot_after"] += 1


def _donors(p: Program, a: int, b: int) -> list[int]:
    """The rows of the neighbours the short shot [a, b) may go to, the shot before first: of its
    kind (live, or the same replay going on: its replayed frames at most REPLAY_GAP_FRAMES apart
    across the cut)."""
    if a == 0 or p.replay[a:b].any() != p.replay[a:b].all():
        return []
    replay = bool(p.replay[a])

    def goes_on(before: int, after: int) -> bool:
        if p.replay[before] != replay or p.replay[after] != replay:
            return False
        return not replay or abs(int(p.shown_index[after]) - int(p.shown_index[before])) <= REPLAY_GAP_FRAMES

    return [d for d, (x, y) in ((a - 1, (a - 1, a)), (b, (b - 1, b))) if goes_on(x, y)]


def eval_match_judge(match, bodies, lens, level) -> Judge:
    """The judge of the module docstring: eval-match's shown fraction of the neighbour's subjects
    from the poses it gives the rows (a first-person picture counts as showing: eval-match never
    counts one as showing nobody)."""
    from camdirector.evaluation.match.measure import EYE_HEIGHT_FRACTION, in_eyes_of, measure_shown
    from camdirector.geometry.transforms import quat_rotate
    from camdirector.pipeline.match.look_along import look_along

    column = match.player_index()
    aims = match.aim_rotations_xyzw()

    def poses_of(program: Program, rows: np.ndarray, row: int) -> tuple[Poses, bool]:
        k = len(rows)
        eyes = int(in_eyes_of(match, program)[row])
        fov = np.repeat(program.vertical_fov_deg[row], k)
        if eyes >= 0:
            feet = match.positions_world[program.shown_index[np.append(row, rows)], eyes]
            if np.all(np.linalg.norm(np.diff(feet, axis=0), axis=1) < JUMP_M):
                lift = np.array([0.0, EYE_HEIGHT_FRACTION * match.players[eyes].height_m, 0.0])
                seen = [
                    look_along(f + lift, quat_rotate(q, np.array([0.0, 0.0, 1.0])), float(fov[0]))
                    for f, q in zip(feet[1:], aims[program.shown_index[rows], eyes])
                ]
                return (np.array([s.position_world for s in seen]), np.array([s.rotation_xyzw for s in seen]), fov), True
        return (np.repeat(program.position[row][None], k, 0), np.repeat(program.rotation[row][None], k, 0), fov), False

    def judge(program: Program, rows: np.ndarray, row: int) -> tuple[float, Poses]:
        poses, through_eyes = poses_of(program, rows, row)
        if through_eyes:
            return 1.0, poses
        held = dataclasses.replace(
            program,
            index=program.index[rows],
            time_s=program.time_s[rows],
            position=poses[0],
            rotation=poses[1],
            vertical_fov_deg=poses[2],
            cut=program.cut[rows],
            shot_id=program.shot_id[rows],
            subjects=[program.subjects[row]] * len(rows),
            overview=program.overview[rows],
            shown_index=program.shown_index[rows],
            replay=program.replay[rows],
        )
        shown = measure_shown(held, bodies, lens, level)  # (k, P)
        subjects = [column[s] for s in program.subjects[row]]
        showing = shown[:, subjects].max(axis=1) if subjects else shown.max(axis=1)
        return float((showing >= SHOWN_FRACTION).mean()), poses

    return judge


def run_match(name: str, minutes: float, delay_s: float) -> dict:
    from camdirector.evaluation.match import evaluate
    from camdirector.geometry.camera import Lens
    from camdirector.precompute.tracks.registry import LevelRegistry

    with tempfile.TemporaryDirectory(prefix=f"edit-bound-{name}-") as tmp:
        match = prepare(name, Path(tmp), minutes)
        result, runs = evaluate.evaluate_match(match, delay_s, directors=["planned"], data_dir=Path(tmp) / "data", seed=0)
        level, interior, bodies = evaluate._measuring(match, LevelRegistry(Path(tmp) / "data"), 0)
        lens = Lens()  # the server's default lens, eval-match's
        run = runs["planned"]
        program, counts = repaired(run.program, eval_match_judge(match, bodies, lens, level), evaluate.SHORT_SHOT_S)
        after = evaluate._figures(match, dataclasses.replace(run, program=program), bodies, lens, level, interior)
    before = result["directors"]["planned"]
    return {
        "repairs": counts,
        "before": {name: f(before) for name, f in FIGURES},
        "after": {name: f(after) for name, f in FIGURES},
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", default=",".join(MATCHES), help="comma-separated match names (default: the real matches)")
    parser.add_argument("--minutes", type=float, default=3.0, help="each match's first minutes (default 3)")
    parser.add_argument("--delay", type=float, default=10.0, help="broadcast delay, s (default 10)")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    matches = {}
    for name in args.only.split(","):
        print(f"{name}: streaming and repairing", file=sys.stderr, flush=True)
        matches[name] = run_match(name, args.minutes, args.delay)
    emit({"benchmark": "edit_window_bound", "minutes": args.minutes, "delay_s": args.delay, "matches": matches}, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
