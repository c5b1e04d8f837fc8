"""The shot builder: a shot's camera for a kind and subjects, placed by ray casts and the grammar.

Every director of ours that places a Toric camera builds its shots here (our director, planned.py;
the rig's takes and candidates, rig.py and takes.py); a plugin director may too (its context's
`builder`, director_contract.py). The shot's camera comes from shots.py with the grammar of
grammar.py: the line of action of a pair is kept, and a cut that shares subjects with the previous
shot must turn 30 degrees. A DUEL or GROUP (not a human's take) whose best place sees its subjects
under `min_visible` over the moments it must cover is shot as a level OVERVIEW of exactly those
subjects when one of its cameras (above them, or a node of the level's graph), allowed by the
30-degree rule, sees them better; its reason says so ("wide: no level duel place sees both"). The
level Toric pictures cannot show a pair far apart along a corridor, seen only from above it over a
shoulder, one above the other (shots.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens
from camdirector.pipeline.match.frame import ShotChoice, ShotKind
from camdirector.pipeline.match.grammar import Grammar
from camdirector.pipeline.match.moments import Moment, MomentBuffer
from camdirector.pipeline.match.program_shot import Shot
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shots import (
    PairWindow,
    Place,
    StaticCamera,
    ToricCamera,
    best_place,
    overview_pose,
    place_grid,
)
from camdirector.pipeline.match.visibility import SubjectVisibility
from camdirector.pipeline.style import Style

ALONE_GAP_S = 0.6  # a killer alone this long before its pair's window is also placed for halfway, s
ALONE_AFTER_S = 0.5  # and for this long after the window closes, s


class ShotBuilder:
    """Makes a shot's camera for a kind and subjects, placed by ray casts and the grammar."""

    def __init__(
        self,
        players: list[str],
        style: Style,
        lens: Lens,
        settings: MatchSettings,
        visibility: SubjectVisibility,
        grammar: Grammar,
        extra_overview_cameras: np.ndarray,
    ):
        self.players, self.style, self.lens = players, style, lens
        self.settings, self.visibility, self.grammar = settings, visibility, grammar
        self.extra_overview_cameras = extra_overview_cameras

    @property
    def upright(self) -> float:
        """The sign of phi where the style's composition is upright (geometry/toric.py: seen from
        phi = +pi/2, A is on the left)."""
        return 1.0 if self.style.screen_a[0] <= self.style.screen_b[0] else -1.0

    def default_place(self) -> Place:
        return Place(self.style.preferred_theta_ratio, self.upright * math.radians(self.style.preferred_phi_deg))

    def cameras(
        self, kind: ShotKind, subjects: tuple[int, ...], moment: Moment, default: bool
    ) -> list[tuple[ToricCamera, Sequence[Place]]]:
        """The Toric cameras a shot may use, each with the places to try (default: the style's only)."""
        if kind == ShotKind.FOLLOW:
            return [
                (
                    ToricCamera(kind, subjects[0], None, self.style, self.lens, self.default_place()),
                    [self.default_place()] if default else place_grid(None),
                )
            ]
        if kind == ShotKind.DUEL:
            i, j = subjects
            left = self.grammar.duel_left(self.players[i], self.players[j])
            orders = [(i, j), (j, i)] if left is None else [(i, j) if self.players[i] == left else (j, i)]
        else:  # GROUP: the two players farthest apart frame the rest
            aims = moment.aims_world[list(subjects)]
            d = np.linalg.norm(aims[:, None] - aims[None], axis=2)
            a, b = np.unravel_index(int(np.argmax(d)), d.shape)
            orders = [(subjects[a], subjects[b]), (subjects[b], subjects[a])]
        grid = [self.default_place()] if default else place_grid(self.upright)
        return [
            (ToricCamera(kind, a, b, self.style, self.lens, self.default_place()), grid)
            for a, b in (orders[:1] if default else orders)
        ]

    def _best(
        self,
        kind: ShotKind,
        subjects: tuple[int, ...],
        moment: Moment,
        cover: list[Moment],
        weights: list[float] | None,
        allowed: Callable[[np.ndarray], np.ndarray] | None,
        pair: PairWindow | None = None,
    ) -> tuple[ToricCamera, Place, float]:
        """The camera (of those cameras() offers at the moment, with the pair window of a planned
        DUEL) and place that best see the subjects over cover, and its score (-1: the grammar
        refuses every place)."""
        best: tuple[ToricCamera, Place, float] | None = None
        for camera, places in self.cameras(kind, subjects, moment, default=False):
            camera.pair = pair
            place, score = best_place(camera, places, cover, subjects, self.visibility, allowed, moment, weights)
            if best is None or score > best[2]:
                best = (camera, place, score)
        assert best is not None  # every kind offers a camera
        return best

    def place_score(
        self, kind: ShotKind, subjects: tuple[int, ...], moment: Moment, cover: list[Moment], weights: list[float]
    ) -> float:
        """How well the best place of a shot from the moment on sees the subjects over cover, [0, 1]."""
        if kind == ShotKind.OVERVIEW:
            return self._overview(subjects, cover, weights)[1]
        return self._best(kind, subjects, moment, cover, weights, None)[2]

    def _overview(
        self,
        subjects: tuple[int, ...],
        cover: list[Moment],
        weights: list[float],
        allowed: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> tuple[CameraPose, float]:
        return overview_pose(
            cover,
            weights,
            subjects,
            self.lens,
            self.visibility,
            self.settings.overview_height_m,
            self.extra_overview_cameras,
            allowed,
        )

    def build(
        self,
        choice: ShotChoice,
        subjects: tuple[int, ...],
        moment: Moment,
        cover: list[Moment],
        previous: Shot | None,
        previous_pose: CameraPose | None,
        start_s: float,
        weights: list[float] | None = None,
        events_s: tuple[float, ...] = (),
        buffer: MomentBuffer | None = None,
    ) -> tuple[Shot | None, float]:
        """A shot showing `subjects` from `moment` on, placed for the moments in `cover` (with
        `weights`, default equal), respecting the 30-degree rule against the previous picture at
        `moment`; and its place's score. None (and -1) when no place respects the rule. A DUEL or
        GROUP whose best place scores under min_visible is a wide OVERVIEW of its subjects when
        one sees them better (module docstring).

        A DUEL planned for events at events_s, s, frames its pair around them only, its first
        subject (the killer) alone elsewhere (shots.py `PairWindow`). When the cut itself shows the
        killer alone, the pair's place is chosen for the events as before, without the 30-degree
        rule (the pair is not on screen at the cut), and the killer's own place from all of the
        grid for the moments it is alone (`_alone_cover`, read from `buffer`), with the rule."""
        if choice.kind == ShotKind.OVERVIEW:
            # everybody when nobody is named and nobody alive (all dead between rounds): a view of the map, not an error
            shown = subjects or tuple(int(i) for i in np.flatnonzero(moment.alive)) or tuple(range(len(moment.alive)))
            pose, seen = self._overview(shown, cover, [1.0] * len(cover) if weights is None else weights)
            return Shot(choice, subjects, StaticCamera(pose), start_s), seen
        previous_framed = set() if previous is None else set(previous.framed(moment.time_s))
        previous_world = None if previous_pose is None else previous_pose.position_world

        def allowed_after(framed: tuple[int, ...]) -> Callable[[np.ndarray], np.ndarray]:
            """The 30-degree rule for a cut from the previous picture to one framing `framed`."""
            shared = list(previous_framed & set(framed))
            return lambda positions: self.grammar.allows_cut(previous_world, moment.aims_world[shared], positions)

        s = self.settings
        pair = (
            PairWindow(subjects[0], events_s, s.pair_before_s, s.pair_after_s, s.reframe_s)
            if events_s and choice.kind == ShotKind.DUEL
            else None
        )
        alone = pair is not None and buffer is not None and pair.weight(moment.time_s) <= 0.0
        allowed = allowed_after(subjects)
        camera, place, score = self._best(choice.kind, subjects, moment, cover, weights, None if alone else allowed, pair)
        if score < s.min_visible and not choice.held:  # a wide view of them may see them better
            pose, seen = self._overview(subjects, cover, [1.0] * len(cover) if weights is None else weights, allowed)
            # a killer shown alone until its kill sees more than a static view seeing the pair under min_visible
            if seen > max(score, 0.0) and (seen >= s.min_visible or not alone):
                what = "both" if choice.kind == ShotKind.DUEL else "them all"
                wide = replace(
                    choice,
                    kind=ShotKind.OVERVIEW,
                    reason=f"{choice.reason}; wide: no level {choice.kind.name.lower()} place sees {what}",
                )
                return Shot(wide, subjects, StaticCamera(pose), start_s), seen
        if alone and score >= 0.0:
            assert pair is not None and buffer is not None  # `alone` needs both
            keep = (pair.keep_index,)
            camera.pair = replace(pair, place=place)
            place, alone_score = best_place(
                camera,
                place_grid(None),
                self._alone_cover(pair, moment, buffer),
                keep,
                self.visibility,
                allowed_after(keep),
                moment,
            )
            score = score if alone_score >= 0.0 else -1.0
        if score < 0.0:
            return None, -1.0
        camera.place = camera.goal = place
        if choice.kind == ShotKind.DUEL:
            assert camera.b_index is not None  # a DUEL's camera frames two
            self.grammar.remember_duel(self.players[camera.a_index], self.players[camera.b_index])
        return Shot(choice, subjects, camera, start_s), score

    @staticmethod
    def _alone_cover(pair: PairWindow, moment: Moment, buffer: MomentBuffer) -> list[Moment]:
        """The moments a planned DUEL's killer is framed alone, its own place is chosen for: the
        cut, halfway to the pair's window when that is over ALONE_GAP_S away, and ALONE_AFTER_S
        after the window closes when the buffer reaches it."""
        now = moment.time_s
        opens = pair.times_s[0] - pair.before_s - pair.ramp_s
        closed = pair.times_s[-1] + pair.after_s + pair.ramp_s + ALONE_AFTER_S
        times = (
            [now]
            + ([0.5 * (now + opens)] if opens - now > ALONE_GAP_S else [])
            + ([closed] if closed <= buffer.horizon_s else [])
        )
        return [buffer.at(t) for t in times]
