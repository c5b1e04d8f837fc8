"""The camera worked out ahead: with a delay, the next frame's program moment is most likely the
next buffered one, known already. After a frame the rig works out, in the worker's idle moments
(its deferred work, before the drawn plan's slices), that moment's CAMERA and VISIBILITY from a
copy of the shot's camera (program_camera.py; a REPLAY's at the moment it replays then), and the
candidates' poses (a REPLAY candidate's at its kill), kept inside the level
(in_level.py) as the program's are, and whether each shows its subjects there (those of the
drawn plan too, once computed: the tick that applies it shows them). The frame takes them when they are its
own: the same moment and time step, the same shot, style and pose shown before, and the camera's
attributes the same objects (cameras change only by assigning them, program_shot.py, so a tick's
new goal or pair window, or a cut, shows); otherwise it computes them as before. A tick that
applies a drawn plan computed by then, keeping the shot, gives the camera its new goal or pair
window before the step: the step ahead is worked out again with them once the plan is computed,
and the tick assigns the very objects it assumed (on the real wipeout's first minute at 30 Hz, 53
of the 67 steps ahead that did not hold were a tick's new goal, at 2-17 ms a frame). What a frame
answers does not depend on whether they were worked out ahead
(tests/pipeline/match/test_match_rig.py). A session with dynamic objects does not look ahead.
So is the lens checked where the window's next frame is answered (`AnswerLens`: about 1 ms a
frame, and up to 20 ms where a pose an edit window gave a frame steps back from a player).
What it saved the frames: docs/casting.md.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from camdirector.geometry.camera import CameraPose
from camdirector.pipeline.match.frame import Candidate, ReplayedMoment, ShotChoice
from camdirector.pipeline.match.in_level import InLevel
from camdirector.pipeline.match.moments import Moment
from camdirector.pipeline.match.program_camera import ProgramCamera
from camdirector.pipeline.match.program_shot import CandidateShot, Shot, ShotCamera, unchanged
from camdirector.pipeline.match.shots import ToricCamera
from camdirector.pipeline.style import Style


@dataclass
class CameraStep:
    """The CAMERA and VISIBILITY stages of a frame with no cut, worked out ahead (module
    docstring): what they made of the shot's camera, and what the frame shows."""

    moment: Moment
    dt_s: float
    shot: Shot  # the shot, and its camera, it is a step of
    camera: ShotCamera
    camera_before: dict[str, Any]  # the camera's attributes it stepped from (compared by identity)
    camera_after: dict[str, Any]  # and those it left
    last_pose: CameraPose | None  # the pose shown before, held when the camera has none
    style: Style
    pose: CameraPose
    flags: list[str]
    visibility: float  # mean share of the framed subjects seen
    cut_short: bool  # whether a cut within the shot would have been short (rig.py, program_camera.py)
    # the camera's attributes the moment's planning tick assigns before the step (a drawn plan's new goal), by name
    assigned: dict[str, Any]

    def holds(self, moment: Moment, dt_s: float, shot: Shot, style: Style, last_pose: CameraPose | None, cut_short: bool) -> bool:
        """Whether it is this frame's step: the same moment, time step, style, pose before and
        answer to whether a cut would be short, from the shot's camera exactly as it is (every camera changes by assigning
        its attributes, so identity tells any change: a tick's new goal or pair window, a cut)."""
        camera = shot.camera
        return (
            self.moment is moment
            and self.cut_short == cut_short
            and self.dt_s == dt_s
            and self.shot is shot
            and self.camera is camera
            and self.style is style
            and self.last_pose is last_pose
            and unchanged(camera, self.camera_before)
        )


@dataclass
class CandidatePoses:
    """The candidates' cameras' poses at a moment (None: an OVERVIEW candidate's, the program's),
    and whether each may be offered from it (`Offerable`)."""

    moment: Moment
    candidates: list[CandidateShot]  # the list they are of (by identity)
    poses: list[CameraPose | None]
    offerable: list[bool]


def step_ahead(
    program_camera: ProgramCamera,
    moment: Moment,
    dt_s: float,
    shot: Shot,
    style: Style,
    last_pose: CameraPose | None,
    cut_short: bool,
    assigned: dict[str, Any],
) -> CameraStep | None:
    """The shot's camera's step to the moment, from a copy of it with the attributes `assigned`
    (those the moment's tick assigns: rig.py), knowing whether a cut within the shot would be
    short (rig.py); None when it has no pose and none was shown before."""
    camera = shot.camera
    ahead = copy.copy(camera)
    vars(ahead).update(assigned)
    stepped = program_camera.step(moment, dt_s, ahead, shot, style.response_time_s, last_pose, cut_short)
    if stepped is None:
        return None
    pose, flags = stepped
    return CameraStep(
        moment,
        dt_s,
        shot,
        camera,
        {**vars(camera), **assigned},
        dict(vars(ahead)),
        last_pose,
        style,
        pose,
        flags,
        program_camera.visibility(moment, pose, shot),
        cut_short,
        assigned,
    )


@dataclass
class AnswerLens:
    """The lens checked where the next frame is answered (program_camera.py widened_for_answer),
    worked out ahead for the window's next frame (module docstring): what it read (the frame's
    pose and flags, the lens answered before, the time step, the shot, and of its camera, which
    goes on moving with the window's end, the camera itself and whom it frames) and what it made
    of them."""

    shown: Moment
    pose_before: CameraPose
    last_fov_deg: float | None
    dt_s: float
    shot: Shot
    camera: ShotCamera
    framed: tuple[int, ...]
    flags_before: list[str]
    pose: CameraPose
    flags: list[str]  # flags_before and those it added

    def holds(
        self, shown: Moment, pose: CameraPose, last_fov_deg: float | None, dt_s: float, shot: Shot, flags: list[str]
    ) -> bool:
        """Whether it is the check of this answer: the same frame's pose and flags (a repair
        settled when answering replaces them), lens before, time step, shot, camera and whom it
        frames at the moment shown."""
        return (
            self.shown is shown
            and self.pose_before is pose
            and self.last_fov_deg == last_fov_deg
            and self.dt_s == dt_s
            and self.shot is shot
            and self.flags_before == flags
            and shot.camera is self.camera
            and shot.framed(shown.time_s) == self.framed
        )


def answer_lens_ahead(
    program_camera: ProgramCamera,
    shown: Moment,
    pose: CameraPose,
    last_fov_deg: float | None,
    dt_s: float,
    shot: Shot,
    flags: list[str],
) -> AnswerLens:
    """The lens check of a frame to answer (program_camera.py widened_for_answer), on a copy of its flags."""
    flags_after = list(flags)
    widened = program_camera.widened_for_answer(shown, pose, last_fov_deg, dt_s, shot, flags_after)
    return AnswerLens(
        shown, pose, last_fov_deg, dt_s, shot, shot.camera, shot.framed(shown.time_s), list(flags), widened, flags_after
    )


# the moment a candidate's monitor shows beside a program moment (a REPLAY candidate's is its kill's: rig.py)
MomentOf = Callable[[ShotChoice, Moment], Moment]
# whether a candidate's pose shows enough of its subjects at the moment its monitor shows (the rig's
# `_offerable`): one is offered only then (issue 41)
Offerable = Callable[[CameraPose, ShotChoice, Moment], bool]


def contained_poses(moments: list[Moment], cameras: list[ToricCamera | None], in_level: InLevel) -> list[CameraPose | None]:
    """The Toric cameras' poses, each at its moment (None for no camera or no pose), inside the
    level (toward each one's anchor), their places tested in one call."""
    poses = [None if cam is None else cam.pose(m) for cam, m in zip(cameras, moments)]
    anchors = [None if cam is None else m.aims_world[cam.anchor_index] for cam, m in zip(cameras, moments)]
    return in_level.contained_many(poses, anchors)


def _judged_poses(
    choices: list[ShotChoice],
    cameras: list[ToricCamera | None],
    shown_at: list[Moment],
    in_level: InLevel,
    offerable: Offerable,
) -> tuple[list[CameraPose | None], list[bool]]:
    """The cameras' poses at the moments their monitors show, inside the level (contained_poses),
    and whether each may be offered from its pose (True where there is none)."""
    poses = contained_poses(shown_at, cameras, in_level)
    return poses, [p is None or offerable(p, choice, at) for p, choice, at in zip(poses, choices, shown_at)]


def candidate_poses(
    moment: Moment, lists: list[list[CandidateShot]], in_level: InLevel, moment_of: MomentOf, offerable: Offerable
) -> list[CandidatePoses]:
    """Each list's candidates' poses beside the program moment, and whether each may be offered."""
    out = []
    for c in lists:
        choices = [choice for choice, _, _ in c]
        poses, offered = _judged_poses(
            choices, [cam for _, cam, _ in c], [moment_of(choice, moment) for choice in choices], in_level, offerable
        )
        out.append(CandidatePoses(moment, c, poses, offered))
    return out


def candidate_views(
    moment: Moment,
    pose: CameraPose,
    candidates: list[CandidateShot],
    ahead: list[CandidatePoses],
    program: ShotCamera,
    in_level: InLevel,
    moment_of: MomentOf,
    offerable: Offerable,
) -> list[Candidate]:
    """The frame's candidates that may be offered: each camera's pose beside the moment
    (moment_of), inside the level (worked out ahead, or now; an OVERVIEW candidate's is the
    program's pose), offered where it shows its subjects (`Offerable`, judged with the pose)."""
    known_poses = next((a for a in ahead if a.moment is moment and a.candidates is candidates), None)
    known = known_poses.poses if known_poses is not None else [None] * len(candidates)
    known_offerable = known_poses.offerable if known_poses is not None else [True] * len(candidates)
    # worked out now: the cameras without a pose ahead, and the one the program took
    now = [cam if cam is not None and (k is None or cam is program) else None for (_, cam, _), k in zip(candidates, known)]
    shown_at = [moment_of(choice, moment) for choice, _, _ in candidates]
    computed, now_offerable = _judged_poses([choice for choice, _, _ in candidates], now, shown_at, in_level, offerable)
    views = []
    for (choice, cam, score), at, asked, now_pose, now_offered, ahead_pose, ahead_offered in zip(
        candidates, shown_at, now, computed, now_offerable, known, known_offerable
    ):
        shown: CameraPose | None
        if cam is None:  # an OVERVIEW's: the level, from the program's pose
            shown, offered = pose, True
        elif asked is not None:
            shown, offered = now_pose, now_offered
        else:
            shown, offered = ahead_pose, ahead_offered
        if shown is not None and offered:
            replay = None if at is moment else ReplayedMoment(at.frame, at.time_s)
            views.append(Candidate(shown, choice, score, replay, at.transforms))
    return views
