"""CAMERA and VISIBILITY of the MATCH rig: every frame, the program shot's camera stepped to the
program moment, a Toric camera whose first subject walls hide pulled in front of the wall (shots.py
`pulled_in`, flagged `pulled_in_front_of_wall`), any director's pose that would lie outside the
level or inside solid moved inside toward the player the shot keeps in view (in_level.py, flagged
`moved_inside_level`), one that would move through a wall kept on that player's side of it (flagged
`kept_this_side_of_wall`) or, for a short move, held where it was (`held_before_wall`), our
director's Toric pose faster than `move_speed_max_m_s` with no wall across it made over several
frames (in_level.py `paced`, flagged `move_paced`) or, where that takes over `move_cut_s`, left to
the rig's cut (`cut_long_move`), its lens widened where a player would stand taller than the framing
band (lens_width.py, flagged `lens_widened`; every director's shots, the baselines' too) or, for a
Toric camera or a wide view of named players (our director's), where the frame cuts off a framed
subject, and zoomed in where those framed subjects stand small (flagged `lens_zoomed`); our
director's pose (Toric or fixed) that the widest lens leaves with a player too tall stepped back
from it, or with no room to step panned off the player (step_back.py, flagged
`stepped_back_from_player`, `panned_off_player`: no cut for the subjects such a pan lets go); a
Toric pose that these degrades left showing none of its subjects replaced by the move a hold held or
a pace slowed (`hold_left_for_cut`) or by a cut to a place that shows them (`cut_to_seen_place`,
`_seen_again`); and the share of the framed subjects' sample points seen from the pose
(visibility.py). In the frame (rig.py) or ahead of it, on a copy of the camera (camera_ahead.py):
the same computation either way.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens
from camdirector.geometry.raycast import RayScene
from camdirector.pipeline.match.first_person import FirstPersonCamera
from camdirector.pipeline.match.grammar import Grammar
from camdirector.pipeline.match.in_level import InLevel
from camdirector.pipeline.match.lens_width import widened_fov_deg
from camdirector.pipeline.match.moments import Moment
from camdirector.pipeline.match.program_shot import Shot, ShotCamera
from camdirector.pipeline.match.settings import MatchSettings
from camdirector.pipeline.match.shot_builder import readable_clearance, within_band
from camdirector.pipeline.match.shots import StaticCamera, ToricCamera, best_place, place_grid, poses_seen
from camdirector.pipeline.match.step_back import stepped_back
from camdirector.pipeline.match.visibility import SubjectVisibility

CUT_TO_SEEN_PLACE = "cut_to_seen_place"  # a degraded pose showing nobody replaced by a cut to a new place
HOLD_LEFT_FOR_CUT = "hold_left_for_cut"  # a hold before a wall showing nobody left for the cut through it
SUBJECTS_LOST = "subjects_lost"  # a degraded pose showing nobody where no re-placement was looked for
STEPPED_BACK = "stepped_back_from_player"  # a pose moved back from a player too near for the widest lens
PANNED_OFF = "panned_off_player"  # a pose with no room to step back panned off the player instead, for a few frames
CUT_LONG_MOVE = "cut_long_move"  # a move pacing would make up in over move_cut_s, a cut instead (rig.py)
PACED = "move_paced"  # a move faster than move_speed_max_m_s with no wall across it made up over the next frames


class ProgramCamera:
    """The CAMERA and VISIBILITY stages of one session (module docstring)."""

    def __init__(
        self,
        settings: MatchSettings,
        visibility: SubjectVisibility,
        ray_scene: RayScene,
        lens: Lens,
        in_level: InLevel,
        grammar: Grammar,
        future: Callable[[float], Moment | None],
    ):
        self.settings, self.subject_visibility, self.ray_scene, self.lens = settings, visibility, ray_scene, lens
        self.in_level, self.grammar, self.future = in_level, grammar, future  # future: the buffered moment at a time, s

    def step(
        self,
        moment: Moment,
        dt_s: float,
        camera: ShotCamera,
        shot: Shot,
        response_time_s: float,
        last_pose: CameraPose | None,
        cut_short: bool = False,
        re_place: bool = True,
    ) -> tuple[CameraPose, list[str]] | None:
        """CAMERA of `shot` by `camera` (its own, or a copy ahead) stepped dt_s to the moment: the
        pose and its flags; the last pose shown held when the camera has none. None when it has
        no pose and none was shown before (a degenerate first shot). A pose that a degrade left
        showing none of the shot's subjects is replaced by a cut (`_seen_again`). Where a cut now
        would leave a shot shorter than the style's `min_shot_s` (`cut_short`, rig.py), a move
        through a wall is held before the wall however far while the hold shows one of the framed
        subjects (`held_before_wall`); it is a cut only where the hold would not. A first-person
        camera's pose is its player's eye as it is (first_person.py), the last pose held while the
        eye is out of the level (`eye_outside_level_held`). Not `re_place` (the edit window's copies
        of a camera, edit_window.py, which a re-placement ends anyway): where a cut to a new place
        would be looked for, the pose is flagged `subjects_lost` instead (a place search costs a
        frame's budget, and one that found nothing was tried again every frame)."""
        camera.advance(moment, dt_s, response_time_s)
        flags: list[str] = []
        if isinstance(camera, FirstPersonCamera):  # a player's eye is where the game let it be (first_person.py),
            eye = camera.pose(moment)
            if self.in_level.inside(eye.position_world) or last_pose is None:
                return eye, flags
            # but for the frames of a teleport a demo interpolates through a wall (2on2_frobodm2: 13 of
            # 43,204 eyes in solid): the picture stays, and the rig cuts where the eye comes out
            return last_pose, ["eye_outside_level_held"]
        pose = camera.pose(moment)
        unheld: CameraPose | None = None  # the pose a hold before a wall, or a pace, replaced
        if pose is not None and isinstance(camera, ToricCamera) and camera.stand_world is None:  # a stand never moves
            pose, pulled = self._pulled_in(moment, pose, dt_s, camera, shot)
            if pulled:
                flags.append("pulled_in_front_of_wall")
        if pose is not None:
            anchor = self._anchor(moment, camera, shot)
            pose, moved = self.in_level.contained(pose, anchor)
            if moved:
                flags.append("moved_inside_level")
            pose = self._stepped_back(moment, pose, camera, shot, flags)  # before the move's wall tests, which judge it too
            if dt_s > 0.0 and last_pose is not None:  # a move, not a cut's first frame
                pose, kept = self.in_level.kept_this_side(last_pose.position_world, pose, anchor)
                if kept:
                    flags.append("kept_this_side_of_wall")
                    pose = self._stepped_back(moment, pose, camera, shot, flags)  # kept nearer its anchor: again
                else:
                    before = pose
                    pose, held = self.in_level.held(
                        last_pose.position_world, pose, anchor, self.lens, self.settings.wall_hold_max_m
                    )
                    if not held and cut_short:
                        pose, held = self._held_showing_all(moment, last_pose, pose, anchor, shot)
                    if held:
                        flags.append("held_before_wall")
                        unheld = before
                        pose = self._stepped_back(moment, pose, camera, shot, flags)
                # our director's moving camera; the baselines' (HLTV's chase camera) move as published
                paced = (
                    self._paced(last_pose, pose, anchor, dt_s, cut_short, flags, moment, shot)
                    if isinstance(camera, ToricCamera)
                    else pose
                )
                if paced is not pose:  # a nearer pose than the move's: a player may be at its lens
                    unheld = pose
                    pose = self._stepped_back(moment, paced, camera, shot, flags)
        if pose is None:
            if last_pose is None:
                return None
            flags.append("pose_held")
            return last_pose, flags
        subjects = _zoomed_for(camera, shot, moment.time_s)
        last_fov_deg = last_pose.vertical_fov_deg if dt_s > 0.0 and last_pose is not None else None  # None: a cut
        if last_fov_deg is None and shot.choice.held:  # a take starts as its candidate's monitor showed it, then zooms
            last_fov_deg = self.lens.vertical_fov_deg
        pose = self._widened(moment, pose, subjects, last_fov_deg, dt_s)
        standing = isinstance(camera, ToricCamera) and camera.stand_world is not None  # a stand that lost them is left too
        # a pan off a player at the lens loses the subjects on purpose, for the frames it passes: no cut for it
        if (flags or standing) and PANNED_OFF not in flags and isinstance(camera, ToricCamera) and shot.choice.replay is None:
            placed, seen_again = self._seen_again(moment, pose, unheld, camera, shot, anchor, last_pose, re_place)
            if seen_again is not None:
                flags.append(seen_again)
            if seen_again == CUT_TO_SEEN_PLACE:  # moved inside the level toward its player, as any pose: maybe too near
                placed = self._stepped_back(moment, placed, camera, shot, flags)
            if seen_again in (CUT_TO_SEEN_PLACE, HOLD_LEFT_FOR_CUT):
                pose = self._widened(moment, placed, subjects, None, dt_s)  # a cut starts at what it needs
        if pose.vertical_fov_deg > self.lens.vertical_fov_deg:
            flags.append("lens_widened")
        elif pose.vertical_fov_deg < self.lens.vertical_fov_deg:
            flags.append("lens_zoomed")
        return pose, flags

    def _stepped_back(
        self, moment: Moment, pose: CameraPose, camera: ShotCamera, shot: Shot, flags: list[str], held_eye: bool = False
    ) -> CameraPose:
        """Our director's pose (Toric or fixed) stepped back from a player too near for the widest
        lens (step_back.py), flagged `stepped_back_from_player` once (`panned_off_player` where it
        could not step and panned off the player where it stands); the baselines' as they are,
        but for held_eye: a first-person camera's pose held where the eye no longer is."""
        if not isinstance(camera, (ToricCamera, StaticCamera)) and not (held_eye and isinstance(camera, FirstPersonCamera)):
            return pose
        framed = shot.framed(moment.time_s)
        stepped = stepped_back(pose, moment, self.subject_visibility, self.lens, self.settings, self.in_level, framed)
        if stepped is None:
            return pose
        flag = PANNED_OFF if stepped[1] else STEPPED_BACK
        if flag not in flags:
            flags.append(flag)
        return stepped[0]

    def _paced(
        self,
        last_pose: CameraPose,
        pose: CameraPose,
        anchor: np.ndarray | None,
        dt_s: float,
        cut_short: bool,
        flags: list[str],
        moment: Moment,
        shot: Shot,
    ) -> CameraPose:
        """A move faster than `move_speed_max_m_s` with no wall across it (a plan's new place for
        the pair around a kill, a hold or a pull in front of a wall let go, an orbit's reframe
        swing): to a viewer a cut, which the program did not flag (on the real duel a 35.6 m jump
        in a frame). One that pacing would make up in `move_cut_s` or less, or where a cut now
        would leave a shot under min_shot_s (cut_short, rig.py) and no event the shot covers
        comes before the pace would, is paced (in_level.py `paced`, flagged `move_paced`); a
        longer one is the rig's cut to where the camera goes (flagged `cut_long_move`): a dolly
        across the arena at that speed shows the kill from nowhere (a hand-built melee's kill, a
        31 m move 0.3 s before it). A paced pose that shows none of the framed subjects where
        the move's does is left for the cut to the move's (`_seen_again`, `hold_left_for_cut`)."""
        s = self.settings
        moved_m = float(np.linalg.norm(pose.position_world - last_pose.position_world))
        if moved_m > s.move_speed_max_m_s * s.move_cut_s:
            arrived_s = moment.time_s + moved_m / s.move_speed_max_m_s
            first = any(moment.time_s <= t <= arrived_s for t in shot.cover_times_s)  # an event before the pace is done
            if (first or not cut_short) and not self.in_level.crossed(last_pose.position_world, pose.position_world):
                flags.append(CUT_LONG_MOVE)
                return pose
        paced, was_paced = self.in_level.paced(last_pose.position_world, pose, anchor, self.lens, s.move_speed_max_m_s * dt_s)
        if was_paced:
            flags.append(PACED)
        return paced

    def _held_showing_all(
        self, moment: Moment, last_pose: CameraPose, pose: CameraPose, anchor: np.ndarray | None, shot: Shot
    ) -> tuple[CameraPose, bool]:
        """The pose's move through a wall held however far (in_level.py `held`) where the hold
        shows one of the framed subjects (framed_seen at least `candidate_seen`): a pan on one of
        a pair rather than a shot under min_shot_s (issue 41: on the real 4on4's first 3 minutes,
        holding only where the pair were both shown left 48 shots under 2 s; where either is, 30,
        at the same kill coverage and visibility), and whether it was; else the pose as it is,
        which the rig cuts to."""
        held_pose, held = self.in_level.held(last_pose.position_world, pose, anchor, self.lens, math.inf)
        subjects = shot.framed(moment.time_s)
        if not held or not subjects:
            return pose, False
        seen = self._seen_from(moment, subjects, [held_pose], Lens(held_pose.vertical_fov_deg, self.lens.aspect))
        return (held_pose, True) if seen.max() >= self.settings.candidate_seen else (pose, False)

    def _seen_from(self, moment: Moment, subjects: tuple[int, ...], poses: list[CameraPose], lens: Lens) -> np.ndarray:
        """(len(poses), len(subjects)): each subject's share framed and seen from each pose (shots.py poses_seen)."""
        return poses_seen(self.subject_visibility, moment, subjects, poses, lens)

    def _widened(
        self, moment: Moment, pose: CameraPose, subjects: tuple[int, ...], last_fov_deg: float | None, dt_s: float
    ) -> CameraPose:
        """The pose with its lens widened (lens_width.py; last_fov_deg None on a cut)."""
        fov_deg = widened_fov_deg(pose, moment, self.subject_visibility, self.lens, self.settings, last_fov_deg, dt_s, subjects)
        return pose if fov_deg == pose.vertical_fov_deg else CameraPose(pose.position_world, pose.rotation_xyzw, fov_deg)

    def widened_for_answer(
        self, moment: Moment, pose: CameraPose, last_fov_deg: float | None, dt_s: float, shot: Shot, flags: list[str]
    ) -> CameraPose:
        """The pose the program answers at the moment its picture shows, its lens widened (never
        narrowed) where a player it shows stands taller than the band there, zooming back from
        the last answered lens (last_fov_deg; None on a cut) at lens_width.py's pace. A pose
        worked at its own moment was widened in `step`; one made for another moment was not: an
        edit window's held first pose of the shot after, a pose held from the frame before
        (`pose_held`). On the real 4on4, 4 of its 9 frames over 0.6 of the frame's height were a
        held first pose at 65 degrees, made for a moment 0.1-1.5 s later. Where even the widest
        lens leaves a player too tall, the pose of the shot (its camera our director's) steps back
        as `step` does (flags takes `stepped_back_from_player`): on the real wipeout, 5 frames over
        0.6 were a pose held from 0.1 s before, as a player ran at the camera. A first-person
        camera's pose is a view through the eyes only where the eye is (step_back.py leaves such
        a view as it is); one held (`eye_outside_level_held`, an edit window's hold) is a camera
        like the others, every director's: the hold is the rig's, not the director's. Of the
        shot's camera it reads only its kind and whom the shot frames (camera_ahead.py
        AnswerLens, worked out ahead, keys on them)."""
        subjects = _zoomed_for(shot.camera, shot, moment.time_s)
        fov_deg = widened_fov_deg(pose, moment, self.subject_visibility, self.lens, self.settings, last_fov_deg, dt_s, subjects)
        if fov_deg <= pose.vertical_fov_deg:
            return pose
        widened = CameraPose(pose.position_world, pose.rotation_xyzw, fov_deg)
        if fov_deg < max(self.settings.widen_max_fov_deg, self.lens.vertical_fov_deg):
            return widened
        return self._stepped_back(moment, widened, shot.camera, shot, flags, held_eye=True)

    def _seen_again(
        self,
        moment: Moment,
        pose: CameraPose,
        unheld: CameraPose | None,
        camera: ToricCamera,
        shot: Shot,
        anchor: np.ndarray | None,
        last_pose: CameraPose | None,
        re_place: bool = True,
    ) -> tuple[CameraPose, str | None]:
        """A Toric pose that a degrade (pulled in front of a wall, held before one, moved inside)
        left showing none of the shot's framed subjects (framed_seen under `candidate_seen`, the
        share eval-match counts a player shown by) is not kept on air (issue 41: frames of nobody
        outside overviews; on the real 4on4's first 3 minutes 300 of its 311 such frames were
        those degrades'). A held pose whose move it held shows them (or a paced pose whose
        whole move does): that move, which the rig cuts to (flagged `hold_left_for_cut`). Else,
        at most once every `seen_again_gap_s` of the program, the camera is re-placed at once at the place of its
        grid that sees its subjects best now and `seen_again_lookahead_s` ahead (the buffered
        future), within the framing band and the 30-degree rule
        (shots.py best_place, as replacement.py re-places at a tick), and the rig cuts to it
        (flagged `cut_to_seen_place`); a DUEL's pair window around its kill re-places the pair's
        place too. Never in the planner's `min_lead_s` before a planned event of the shot (its
        cuts keep off them too: on the real 4on4 re-placing there lost 2 more kills). Where no
        place shows them, the pose is kept. The flag, None when the pose is kept."""
        s, now = self.settings, moment.time_s
        subjects = shot.framed(now)
        if not subjects or any(0.0 <= t - now <= s.min_lead_s for t in shot.cover_times_s):
            return pose, None  # no cut in the last moments before a planned event (the planner's min_lead_s)
        tried = [pose] if unheld is None else [pose, unheld]
        # (len(tried),) the best-shown subject
        seen = self._seen_from(moment, subjects, tried, Lens(pose.vertical_fov_deg, self.lens.aspect)).max(axis=1)
        if seen[0] >= s.candidate_seen:
            return pose, None
        aims = moment.aims_world[list(subjects)]
        shown_world = pose.position_world if last_pose is None else last_pose.position_world  # the cut is from it
        turned = self.grammar.allows_cut
        if unheld is not None and seen[1] >= s.candidate_seen and turned(shown_world, aims, unheld.position_world)[0]:
            return unheld, HOLD_LEFT_FOR_CUT
        if camera.seen_again_s is not None and moment.time_s - camera.seen_again_s < s.seen_again_gap_s:
            return pose, None
        if not re_place:
            return pose, SUBJECTS_LOST
        band = within_band(self.subject_visibility, self.lens, s, subjects, moment)

        def allowed(positions_world: np.ndarray) -> np.ndarray:
            return np.asarray(band(positions_world) & turned(shown_world, aims, positions_world))

        pair = camera.pair if camera.split and camera.pair is not None and camera.pair.weight(moment.time_s) > 0.0 else None
        on_air = camera.place if pair is None or pair.place is None else pair.place  # around a kill, the pair's place
        side = None if camera.b_index is None else math.copysign(1.0, on_air.phi_rad)  # a pair keeps its line of action
        # judged now and a little ahead, in the buffered future, so that it is not lost again at once
        ahead = self.future(moment.time_s + s.seen_again_lookahead_s)
        cover = [moment] if ahead is None else [moment, ahead]
        place, score = best_place(camera, place_grid(side), cover, subjects, self.subject_visibility, allowed, moment)
        if score < s.candidate_seen:
            return pose, None
        kept = (camera.place, camera.goal, camera.pair, camera.reach_m, camera.seen_again_s, camera.stand_world)
        camera.place = camera.goal = place
        camera.stand_world = None  # on its torus again
        if pair is not None:  # the picture is the pair's place now: both re-placed
            camera.pair = dataclasses.replace(pair, place=place)
        camera.reach_m, camera.seen_again_s = None, moment.time_s
        placed = camera.pose(moment)
        if placed is None:  # degenerate now (scored ahead only): the camera as it was
            camera.place, camera.goal, camera.pair, camera.reach_m, camera.seen_again_s, camera.stand_world = kept
            return pose, None
        return self.in_level.contained(placed, anchor)[0], CUT_TO_SEEN_PLACE

    @staticmethod
    def _anchor(moment: Moment, camera: ShotCamera, shot: Shot) -> np.ndarray | None:
        """(3,) m: the aim point of the player the shot keeps in view (a Toric camera's anchor,
        else its first framed subject); None for a shot of nobody."""
        framed = shot.framed(moment.time_s)
        anchor = camera.anchor_index if isinstance(camera, ToricCamera) else framed[0] if framed else None
        return None if anchor is None else np.asarray(moment.aims_world[anchor], dtype=np.float64)

    def visibility(self, moment: Moment, pose: CameraPose, shot: Shot) -> float:
        """VISIBILITY: the mean share of the shot's framed subjects seen from the pose (1 for none)."""
        subjects = shot.framed(moment.time_s)
        return float(self.subject_visibility.visible_share(pose.position_world, moment, subjects).mean()) if subjects else 1.0

    def _pulled_in(
        self, moment: Moment, pose: CameraPose, dt_s: float, camera: ToricCamera, shot: Shot
    ) -> tuple[CameraPose, bool]:
        """The Toric shot's pose pulled in front of a wall (shots.py `pulled_in`) when walls hide
        most of its first subject, kept only if it frames the shot's subjects better (their mean
        seen share, framed_seen): close to A, a pair far apart may no longer fit. On 90 s of the
        4on4 on dm2 this kept program visibility 0.58 and kill coverage 0.60 (0.38 and 0.53 with no
        pull; 0.52 and 0.63 judging by the worst-seen subject; 0.56 and 0.57 pulling always).
        Pulled in or not, the camera keeps a readable distance from the framed subjects
        (shot_builder.py readable_clearance): it comes in no nearer, and a place that has come
        nearer steps back (shots.py `stepped_back`, not flagged: the place's own camera, farther
        along its line) where the level's places test accepts the point. Whether it was pulled in."""
        s, subjects = self.settings, shot.framed(moment.time_s)
        clearance = readable_clearance(self.subject_visibility, self.lens, s, subjects or (camera.anchor_index,), moment)
        hidden = self.subject_visibility.visible_share(pose.position_world, moment, (camera.anchor_index,))[0, 0] < s.pull_below
        reach_before = camera.reach_m
        pulled, moved = camera.pulled_in(
            moment, pose, bool(hidden), self.ray_scene, dt_s, s.pull_margin_m, s.pull_regrow_m_s, clearance
        )
        if moved and subjects:
            seen = self._seen_from(moment, subjects, [pose, pulled], self.lens).mean(axis=1)
            if not (seen[1] > seen[0] or (reach_before is not None and not hidden)):  # going back out: at its pace
                camera.reach_m = None
                pulled, moved = pose, False
        back = camera.stepped_back(moment, pulled, self.ray_scene, s.pull_margin_m, clearance)
        # a step back out of the level (above an open level's box) would be moved in again, nearer (in_level.py)
        return (back if back is pulled or self.in_level.inside(back.position_world) else pulled), moved


def _zoomed_for(camera: ShotCamera, shot: Shot, time_s: float) -> tuple[int, ...]:
    """The players the lens zooms on and widens to show when the frame cuts them off (lens_width.py):
    those our director's Toric camera or wide view (an OVERVIEW's, none where it names nobody)
    frames at time_s; none for the baselines' and the eyes, which keep what they frame."""
    return (shot.framed(time_s) or ()) if isinstance(camera, (ToricCamera, StaticCamera)) else ()
