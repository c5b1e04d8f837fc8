"""Drawn plans: a director's decision taken off the frame path (issue 29), for a director that
`plans_ahead` (director_contract.py; ours, planned.py).

A plan is drawn at a tick for the buffered moment of the next, `plan_interval_s` later, and
applied then (the moment it was made for; made for the tick that drew it, one kill in 14 of the
real duel's first 3 minutes went unshown, 0.786 -> 0.714 kill coverage): drawn, it holds what it
reads (the buffer's view, a copy of the shot's camera, the last pose), and the session's worker
computes it in slices of `PLAN_SLICE_S` in its idle moments (infra/slices.py; the pause points
are the place searches' ray casts, shots.py `framed_seen`). A plan is applied at the first tick by
which it needed at most `plan_work_per_tick` of work per tick since it was drawn (its work counted
in camera-point pairs, the same on any machine); until then no other plan is drawn (flag
`plan_late`), and each tick computes it up to that much, whatever the idle moments left. Applied
by its work, the program does not depend on when, in how many slices or on how fast a machine it
was computed, only on its inputs: a take or a style change, which would change what a drawn plan
reads, finishes it first (rig.py). The first shot and a take's are planned at once; the
baselines (cheap) and a session with dynamic objects (whose ray scene every frame moves) plan in
the frame. What a plan costs, and what drawing it saved the frames: docs/casting.md.
"""

from __future__ import annotations

from dataclasses import dataclass

from camdirector.infra.slices import SlicedRun
from camdirector.pipeline.match.frame import PlannedCut, ShotChoice
from camdirector.pipeline.match.program_shot import CandidateShot, Shot
from camdirector.pipeline.match.shots import Place

PLAN_SLICE_S = 0.002  # a drawn plan is computed this long per idle moment of the worker, s


@dataclass
class PlanResult:
    """What one planning tick decided, applied to the program at once or at the next tick."""

    shot: Shot | None  # the cut, None: the current shot goes on
    goal: Place | None  # the current Toric camera's new goal (re-placed for visibility)
    pair_place: Place | None  # its pair window's new place (re-placed for visibility)
    held: ShotChoice | None  # the take held from now on (a fallback when its subject died)
    candidates: list[CandidateShot]
    planned_cuts: list[PlannedCut]  # the director's planned cuts (MatchRig.planned_cut)
    flags: list[str]


@dataclass
class DrawnPlan:
    """A plan drawn at a tick with what it reads, computed in slices until the tick that applies
    it (module docstring)."""

    current: Shot | None
    run: SlicedRun[PlanResult] | None  # None once finished (a snapshot pickles the rig)
    result: PlanResult | None = None
    work: float = 0.0  # its whole work once finished, camera-point pairs (infra/slices.py)
    ticks: int = 0  # the ticks since it was drawn

    def finish(self) -> PlanResult:
        if self.run is not None:
            self.result, self.work, self.run = self.run.finish(), self.run.work, None
        assert self.result is not None  # a run finished leaves its result
        return self.result

    def due(self, work_per_tick: float) -> bool:
        """At a tick: whether it is applied now, i.e. whether its whole work is at most
        work_per_tick per tick since it was drawn. Computes it up to that much (what the idle
        moments left); the answer depends on its work alone, not on time."""
        self.ticks += 1
        allowed = self.ticks * work_per_tick
        if self.run is not None and self.run.run_until(allowed):
            self.finish()
        return self.run is None and self.work <= allowed
