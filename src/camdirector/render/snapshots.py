"""What a session's monitors show (issue 16), described for the render process (monitor.py).

A view (`ViewQuery`, infra/channels.py: what crosses from the front to the worker) is one of:
- `program`: what the session's camera sees now (its last answered pose, lens and aspect);
- `candidate`: in a MATCH session, the camera of the candidate shot of the given players;
- `cut_before`, `cut_after`: the last frame before the session's last cut and the cut's own;
- `top`: the world from straight above (static objects and the level), for the dashboard's top
  view: drawn once per session.
Moving objects are drawn at their latest transforms (as of the cut for both cut views), targets
at theirs (in each of the cut's two frames for the cut views; a MATCH session's players at the
program's moment, which the broadcast delay puts behind the game).

A `RenderJob` is a snapshot taken on the worker's main thread between two frames: the pose and
every moving object's transform copied into arrays (tens of microseconds for a hundred moving
objects), so the render itself runs in another process while the session goes on. The meshes go
to that process once per session (`scene_geometry`). A view that cannot be drawn (no pose yet,
a delay still filling, no such candidate, no cut yet; a top view of a world with no geometry) is
a placeholder image that says why, not an error: a monitor keeps its place on a director's wall.
A camera view of a session whose scene has no world at all (no object, no level: only targets)
is drawn, the targets against the sky, under a banner that says so (`note`). A camera view labels
its targets with their names (`TargetLabel`, drawn by geometry/labels.py), and says which it
labelled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from camdirector.geometry.camera import CameraPose, Lens
from camdirector.geometry.transforms import quat_to_matrix
from camdirector.infra.channels import MAX_HEIGHT_PX, MIN_SIDE_PX, ViewQuery
from camdirector.pipeline.session import Session
from camdirector.pipeline.style import Rig

TOP_VIEW_LONG_SIDE_PX = 512  # the top view's longer side; the other follows the world's extent
NO_WORLD_NOTE = "no world geometry: the scene has no object and no level, only its targets"

# Colours, linear RGB in [0, 1]. A target in its team's colour (the dashboard's TEAM_COLOURS, in the
# same order), so a monitor matches the top view: team 0, every target outside a MATCH session
# (worker/codec.py refuses a team there), is the dashboard's target orange.
STATIC_RGB = (0.60, 0.60, 0.62)
LEVEL_RGB = (0.62, 0.60, 0.56)
LEVEL_CHECKER_M = 2.0
MOVING_RGB = (0.30, 0.45, 0.70)
TARGET_RGB = (0xE0 / 255, 0x7B / 255, 0x00 / 255)
TEAM_RGB = (
    TARGET_RGB,
    (0x8E / 255, 0x24 / 255, 0xAA / 255),
    (0x2E / 255, 0x7D / 255, 0x32 / 255),
    (0x79 / 255, 0x55 / 255, 0x48 / 255),
)


@dataclass(frozen=True)
class MeshPart:
    """One mesh to draw: static ones in the world frame, moving ones (objects, targets) local."""

    part_id: str
    vertices: np.ndarray  # (n, 3) float32, m
    faces: np.ndarray  # (m, 3) int32
    rgb: tuple[float, float, float]
    checker_m: float = 0.0
    moving: bool = False


@dataclass(frozen=True)
class TargetLabel:
    """The name label over one target (geometry/labels.py): its display name, or in a MATCH
    session its id when it has none; targets of other rigs without a name have no label."""

    part_id: str  # the target's moving part, `target:<id>`
    text: str
    head_local: np.ndarray  # (3,) float64 m: the top of the target's mesh, in its local frame
    rgb: tuple[float, float, float]  # its team's colour, as its mesh's


@dataclass(frozen=True)
class SceneGeometry:
    """Every mesh of a session, and its targets' labels, sent to the render process once per session."""

    parts: tuple[MeshPart, ...]
    labels: tuple[TargetLabel, ...] = ()

    @property
    def has_world(self) -> bool:
        """Whether anything besides the targets and moving objects is there (static objects, a level)."""
        return any(not p.moving for p in self.parts)


@dataclass(frozen=True)
class RenderJob:
    """One picture to make: a snapshot of the session (module docstring)."""

    session_id: str
    query: ViewQuery
    frame: int | None  # the frame the picture shows (None: the top view, a placeholder)
    pose: CameraPose | None  # None: the top view, or a placeholder
    aspect: float  # the session lens's width / height
    moving_ids: tuple[str, ...]  # part ids of the moving parts, in the order of the arrays
    positions_world: np.ndarray  # (k, 3) float64, m
    rotations_xyzw: np.ndarray  # (k, 4) float64
    scales: np.ndarray  # (k, 3) float64
    placeholder: str | None = None  # why there is no picture; None: draw it
    note: str | None = None  # drawn as a banner over the picture (a world without geometry)

    @property
    def size_px(self) -> tuple[int, int]:
        """(width, height) of a camera view: the query's, the height from the aspect if not given."""
        q = self.query
        height = q.height_px or int(min(max(round(q.width_px / self.aspect), MIN_SIDE_PX), MAX_HEIGHT_PX))
        return q.width_px, height

    @property
    def lens(self) -> Lens:
        """The pose's field of view at the picture's own aspect (the session's unless both sides were given)."""
        width, height = self.size_px
        assert self.pose is not None  # only a camera view's picture has a lens
        return Lens(vertical_fov_deg=self.pose.vertical_fov_deg, aspect=width / height)


def scene_geometry(session: Session) -> SceneGeometry:
    """The session's meshes: static objects and the level in the world frame, then its moving
    objects and targets in their local frames (ids `object:<id>` and `target:<id>`)."""
    parts = [
        MeshPart(f"static:{k}", _f32(mesh.vertices), _i32(mesh.faces), STATIC_RGB)
        for k, mesh in enumerate(session.static_meshes_world)
    ]
    if session.level_mesh_world is not None:
        mesh = session.level_mesh_world
        parts.append(MeshPart("level", _f32(mesh.vertices), _i32(mesh.faces), LEVEL_RGB, checker_m=LEVEL_CHECKER_M))
    for object_id, (mesh, _) in session.dynamic.items():
        parts.append(MeshPart(f"object:{object_id}", _f32(mesh.vertices), _i32(mesh.faces), MOVING_RGB, moving=True))
    labels = []
    match = session.style.rig == Rig.MATCH
    for target in session.targets:
        rgb = TEAM_RGB[target.team % len(TEAM_RGB)]
        parts.append(MeshPart(f"target:{target.id}", _f32(target.mesh.vertices), _i32(target.mesh.faces), rgb, moving=True))
        text = target.display_name or (target.id if match else "")
        if text:
            vertices = target.mesh.vertices
            low, high = vertices.min(axis=0), vertices.max(axis=0)
            head = np.array([0.5 * (low[0] + high[0]), high[1], 0.5 * (low[2] + high[2])])
            labels.append(TargetLabel(f"target:{target.id}", text, head, rgb))
    return SceneGeometry(tuple(parts), tuple(labels))


def render_job(session: Session, query: ViewQuery) -> RenderJob:
    """The snapshot for `query` (module docstring); never raises for a view it cannot draw."""
    dynamic, targets = session.dynamic, session.view_target_transforms()
    frame, pose, placeholder = None, None, None
    state = session.last_state
    match = None if state is None else state.match  # the MATCH rig's part: the delay buffer, the candidates
    if query.shot == "top":
        pass
    elif state is None or state.pose is None:
        placeholder = (
            "buffering: the broadcast delay is still filling, no camera yet"
            if match is not None and match.buffering
            else "no camera yet: no frame answered"
        )
    elif query.shot == "program":
        frame, pose = state.frame, state.pose
    elif query.shot == "candidate":
        wanted = set(query.subjects)
        found = [] if match is None else [c for c in match.candidates if set(c.shot.subject_ids) == wanted]
        if found:  # drawn at its own moment: a REPLAY candidate's is its kill's, the others' the program's
            view = found[0]
            frame, pose = state.frame if view.replay_of is None else view.replay_of.frame, view.pose
            targets = targets if view.transforms is None else view.transforms
        else:
            placeholder = (
                f"no candidate shot of {', '.join(query.subjects)} now"
                if match is not None
                else "candidate shots are a MATCH session's"
            )
    else:
        cut = session.last_cut
        if cut is None:
            placeholder = "no cut yet"
        else:
            after = query.shot == "cut_after"
            frame, pose = (cut.frame, cut.pose_after) if after else (cut.frame_before, cut.pose_before)
            dynamic, targets = cut.dynamic, cut.targets_after if after else cut.targets_before
    note = None
    if pose is not None and not (session.static_meshes_world or session.level_mesh_world is not None or dynamic):
        note = NO_WORLD_NOTE
    moving = [(f"object:{object_id}", transform) for object_id, (_, transform) in dynamic.items()]
    moving += [(f"target:{t.id}", transform) for t, transform in zip(session.targets, targets)]
    transforms = [transform for _, transform in moving]
    return RenderJob(
        session_id=session.id,
        query=query,
        frame=frame,
        pose=pose,
        aspect=session.lens.aspect,
        moving_ids=tuple(part_id for part_id, _ in moving),
        positions_world=_stack([tf.position_world for tf in transforms], 3),
        rotations_xyzw=_stack([tf.rotation_xyzw for tf in transforms], 4),
        scales=_stack([tf.scale for tf in transforms], 3),
        placeholder=placeholder,
        note=note,
    )


def _stack(rows: list[np.ndarray], width: int) -> np.ndarray:
    return np.array(rows, dtype=np.float64).reshape(len(rows), width)


def _f32(vertices: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(vertices, dtype=np.float32)


def _i32(faces: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(faces, dtype=np.int32)


def label_heads(job: RenderJob, labels: tuple[TargetLabel, ...]) -> np.ndarray:
    """(n, 3) float64 m: where each label's head is in the job's snapshot (its target's transform)."""
    if not labels:
        return np.zeros((0, 3))
    matrices = rigid_matrices(job)
    row = {part_id: k for k, part_id in enumerate(job.moving_ids)}
    return np.stack([matrices[row[label.part_id]] @ np.append(label.head_local, 1.0) for label in labels])[:, :3]


def rigid_matrices(job: RenderJob) -> np.ndarray:
    """(k, 4, 4) float64 local-to-world matrices of the job's moving parts (RigidTransform.matrix, batched)."""
    m = np.zeros((len(job.moving_ids), 4, 4))
    m[:, 3, 3] = 1.0
    if len(m):
        m[:, :3, :3] = quat_to_matrix(job.rotations_xyzw) * job.scales[:, None, :]
        m[:, :3, 3] = job.positions_world
    return m
