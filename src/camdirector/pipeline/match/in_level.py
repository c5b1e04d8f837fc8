"""Every camera inside the level (issue 41, item 1): the last step of CAMERA for the program's pose
and the candidates' poses, whichever director placed them.

A pose whose centre the level's places test (geometry/inside.py: outside the level mesh's box, or
inside solid) rejects is moved along the line from its anchor (the aim point of the player the
shot keeps in view; with none, the level's camera node nearest the pose) toward the anchor: to
`margin_m` short of the first level face on that line and inside the box, as HLTV's chase camera
comes in front of a wall; a point there that the test still rejects (a line grazing a corner) is
taken nearer the anchor, down to the anchor itself, and where even the anchor is rejected, the
level's camera node nearest it (the precompute's camera places). The rotation is kept: on the
line through the anchor the anchor stays where the frame had it. A pose the test accepts is left
alone, so a director's framing changes only where it would have shown the level from outside.

A program camera that moves through level geometry from one frame to the next (its orbit round
a subject carried past a wall) is kept on its anchor's side the same way (`kept_this_side`);
where that fails, a short move (`wall_hold_max_m`: a corner passed) holds the camera where it
was, turned to keep its anchor where the frame had it (`held`), and a longer one is a cut (rig.py):
cuts to places, never sweeps through walls. A move with no geometry across it that is faster than
the settings' top speed goes that far along its line, turned the same way (`paced`; program_camera.py
decides which moves are paced and which are cuts): no jump a viewer would take for a cut.

Costs: one places test (RAYS rays) per new camera centre; the last few centres' answers are kept,
so a static camera is tested once; two rays per program frame that moves (the sweep); more rays
only where a test fails.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens, level_look_rotation, project_to_screen
from camdirector.geometry.inside import LevelInterior

REMEMBERED = 16  # camera centres whose answers are kept (the program's, the candidates' and a drawn plan's)
NEARER = (0.5, 0.25, 0.0)  # fractions of the way to the anchor tried when the wall's margin still fails the test


class InLevel:
    """The containment of one session's cameras (module docstring). interior: the level's places
    test, None without a level (nothing to contain); nodes_world (k, 3) m: the level's camera
    nodes, anchors for a pose without a subject."""

    def __init__(self, interior: LevelInterior | None, nodes_world: np.ndarray, margin_m: float):
        self.interior, self.nodes_world, self.margin_m = interior, nodes_world, margin_m
        self._answers: OrderedDict[bytes, bool] = OrderedDict()  # centre's bytes -> inside

    def inside(self, position_world: np.ndarray) -> bool:
        """Whether the places test accepts the point (3,) m (remembered for the last REMEMBERED)."""
        if self.interior is None:
            return True
        known = self._answers.get(np.asarray(position_world, dtype=np.float64).tobytes())
        if known is None:
            known = not bool(self.interior.bad(position_world)[0])
            self._remember(position_world, known)
        return known

    def _remember(self, position_world: np.ndarray, inside: bool) -> None:
        self._answers[np.asarray(position_world, dtype=np.float64).tobytes()] = inside
        if len(self._answers) > REMEMBERED:
            self._answers.popitem(last=False)

    def inside_many(self, positions_world: np.ndarray) -> np.ndarray:
        """(n,) bool: `inside` of each of (n, 3) points m, those not remembered tested in one call
        (a frame's candidates, a step back's places at one distance)."""
        keys = [np.asarray(p, dtype=np.float64).tobytes() for p in positions_world]
        if self.interior is None:
            return np.ones(len(keys), dtype=bool)
        new = [i for i, key in enumerate(keys) if key not in self._answers]
        answers = dict(self._answers)
        if new:
            for i, bad in zip(new, self.interior.bad(np.asarray(positions_world)[new]).tolist()):
                answers[keys[i]] = not bad
                self._remember(positions_world[i], not bad)
        return np.array([answers[key] for key in keys], dtype=bool)

    def contained_many(self, poses: list[CameraPose | None], anchors: list[np.ndarray | None]) -> list[CameraPose | None]:
        """`contained` of each pose with its anchor (None stays None), the new centres tested in
        one call (a frame's candidates)."""
        centres = [p.position_world for p in poses if p is not None]
        if centres:
            self.inside_many(np.array(centres))
        return [None if p is None else self.contained(p, a)[0] for p, a in zip(poses, anchors)]

    def crossed(self, from_world: np.ndarray, to_world: np.ndarray) -> bool:
        """Whether the segment between two camera centres (3,) m meets level geometry (crossed_many)."""
        return bool(self.crossed_many(from_world, np.asarray(to_world)[None])[0])

    def crossed_many(self, from_world: np.ndarray, to_world: np.ndarray) -> np.ndarray:
        """(n,) bool: whether the segment from one camera centre (3,) m to each of (n, 3) meets
        level geometry, cast both ways: a segment grazing an edge can hit one way and miss the
        other (Embree's single-ray and packet kernels round apart), and a move that might touch a
        wall is treated as one that does (eval-match casts the whole program's moves in one call)."""
        to = np.asarray(to_world, dtype=np.float64).reshape(-1, 3)
        if self.interior is None or not len(to):
            return np.zeros(len(to), dtype=bool)
        start = np.broadcast_to(np.asarray(from_world, dtype=np.float64), to.shape)
        reach = self.interior.reach(np.concatenate([start, to]), np.concatenate([to, start]))
        return np.asarray((reach < 1.0).reshape(2, len(to)).any(axis=0))

    def contained(self, pose: CameraPose, anchor_world: np.ndarray | None) -> tuple[CameraPose, bool]:
        """The pose, moved inside toward the anchor (3,) m if the test rejects it (module
        docstring), and whether it moved."""
        position = pose.position_world
        if self.inside(position):
            return pose, False
        if anchor_world is None:
            if not len(self.nodes_world):
                return pose, False
            anchor_world = self._nearest_node(position)
        anchor = np.asarray(anchor_world, dtype=np.float64)
        point = self._before_wall(anchor, position)
        if point is None:
            return pose, False
        tried = [point, *(anchor + fraction * (point - anchor) for fraction in NEARER)]
        if len(self.nodes_world):
            tried.append(self._nearest_node(anchor))  # the anchor itself rejected (a dead player's chest in the floor)
        point = next((p for p in tried[:-1] if self.inside(p)), tried[-1])
        return CameraPose(point, pose.rotation_xyzw, pose.vertical_fov_deg), True

    def _nearest_node(self, position: np.ndarray) -> np.ndarray:
        """(3,) m: the level's camera node nearest the position (3,) m."""
        node: np.ndarray = self.nodes_world[np.argmin(np.linalg.norm(self.nodes_world - position, axis=1))]
        return node

    def kept_this_side(
        self, from_world: np.ndarray, pose: CameraPose, anchor_world: np.ndarray | None
    ) -> tuple[CameraPose, bool]:
        """A camera moving from `from_world` (3,) m to the pose through level geometry, kept on
        its anchor's side instead: the pose moved to margin_m short of the first wall on the line
        from its anchor (3,) m, as `contained` moves it, when the move there crosses nothing and
        the place is inside; else the pose as it is (the rig cuts to it: rig.py), and whether it
        moved. A camera orbiting its subject past a corner stays in the subject's room rather
        than cutting at every wall its orbit meets."""
        if anchor_world is None or not self.crossed(from_world, pose.position_world):
            return pose, False
        point = self._before_wall(np.asarray(anchor_world, dtype=np.float64), pose.position_world)
        if point is None or self.crossed(from_world, point) or not self.inside(point):
            return pose, False
        return CameraPose(point, pose.rotation_xyzw, pose.vertical_fov_deg), True

    def held(
        self, from_world: np.ndarray, pose: CameraPose, anchor_world: np.ndarray | None, lens: Lens, hold_max_m: float
    ) -> tuple[CameraPose, bool]:
        """A camera moving from `from_world` (3,) m to the pose through level geometry by at most
        hold_max_m, m: held where it was, turned to show its anchor (3,) m where the pose shows it
        (the pose's rotation where the anchor is behind it, or with none); else the pose as it is,
        and whether it was held. A move that short is the camera carried past a corner (a wall
        the pull in front of walls switched to, an edge the orbit clips), not a new place: the
        rig would cut to a view a step away."""
        moved_m = float(np.linalg.norm(pose.position_world - from_world))
        if moved_m > hold_max_m or not self.crossed(from_world, pose.position_world):
            return pose, False
        return _turned_from(from_world, pose, anchor_world, lens), True

    def paced(
        self, from_world: np.ndarray, pose: CameraPose, anchor_world: np.ndarray | None, lens: Lens, step_max_m: float
    ) -> tuple[CameraPose, bool]:
        """A camera moving from `from_world` (3,) m to the pose farther than step_max_m, m, with no
        level geometry between: moved step_max_m along that line, turned to show its anchor (3,)
        m where the pose shows it (as `held` turns), and whether it was; else the pose as it is (a
        move through a wall is the rig's cut). Between two frames a jump no wall lies across (a
        pull in front of a wall let go, a hold released, an orbit's reframe swing) is to a viewer
        a cut that the program never flagged (eval-match `jumped_without_cut`); paced, it is a
        move. On the segment of two centres inside the level that meets no geometry, the point is
        inside too."""
        offset = pose.position_world - from_world
        moved_m = float(np.linalg.norm(offset))
        if moved_m <= step_max_m or self.crossed(from_world, pose.position_world):
            return pose, False
        return _turned_from(from_world + offset * (step_max_m / moved_m), pose, anchor_world, lens), True

    def _before_wall(self, anchor: np.ndarray, position: np.ndarray) -> np.ndarray | None:
        """(3,) m: the point margin_m short of where the line from the anchor (3,) to the position
        (3,) first meets a level face or leaves the level's box, or the position if it does
        neither; None when the two coincide."""
        offset = position - anchor
        length_m = float(np.linalg.norm(offset))
        if length_m < 1e-6 or self.interior is None:
            return None
        reach_m = float(self.interior.reach(anchor, position)[0]) * length_m
        reach_m = min(reach_m, _box_exit(anchor, offset / length_m, self.interior.low, self.interior.high))
        if reach_m >= length_m:
            return position
        point: np.ndarray = anchor + max(reach_m - self.margin_m, 0.0) / length_m * offset
        return point


def _turned_from(position_world: np.ndarray, pose: CameraPose, anchor_world: np.ndarray | None, lens: Lens) -> CameraPose:
    """The pose's lens at position_world (3,) m, turned to keep its anchor (3,) m where the pose's
    frame has it (the pose's rotation where the anchor is behind it, or with none)."""
    rotation = pose.rotation_xyzw
    if anchor_world is not None:
        frame_lens = Lens(pose.vertical_fov_deg, lens.aspect)
        screen = project_to_screen(pose, frame_lens, anchor_world)[0]
        if np.all(np.isfinite(screen)) and np.linalg.norm(anchor_world - position_world) > 1e-6:
            rotation = level_look_rotation(position_world, anchor_world, screen.tolist(), frame_lens)
    return CameraPose(np.array(position_world, dtype=np.float64), rotation, pose.vertical_fov_deg)


def _box_exit(origin: np.ndarray, direction: np.ndarray, low: np.ndarray, high: np.ndarray) -> float:
    """Distance, m, along the unit direction (3,) from origin (3,) to where the ray leaves the box
    [low, high] (0 when the origin is outside it)."""
    if np.any(origin < low) or np.any(origin > high):
        return 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        wall = np.where(direction > 0.0, high, low)
        far = np.where(direction != 0.0, (wall - origin) / direction, np.inf)
    return float(far.min())
