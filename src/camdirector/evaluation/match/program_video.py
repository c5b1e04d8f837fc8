"""The video of `camdirector eval-match`: a director's program rendered offscreen with EGL.

Each program moment is drawn from its camera at VIDEO_SIZE_PX (a replay's at the match frame it
shows again): the level mesh and the players'
capsules coloured by team (dead players are left out: the match file keeps their bodies standing
where they fell, which on screen would read as a player who is still fighting; so is the player
in whose eyes a first-person moment is, measure.py `in_eyes_of`, as the game's own view), each living player
in the picture labelled over its head with its name, or its id where the game gave none
(geometry/labels.py, as the dashboard's monitors). A small top view
of the level sits in the top right corner, with every living player as a dot of its team's colour
and the program camera as a white dot. Frames play at the program's rate, so the video runs in
game time.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from camdirector.evaluation.match.match_file import MatchRecording
from camdirector.evaluation.match.measure import Program, in_eyes_of, player_mesh
from camdirector.geometry.camera import CameraPose, Lens, project_to_screen
from camdirector.geometry.labels import PlacedLabel, draw_labels
from camdirector.geometry.transforms import RigidTransform, matrix_to_quat
from camdirector.precompute.tracks.registry import LevelRegistry

VIDEO_SIZE_PX = (480, 270)  # width, height; even for yuv420p
INSET_SIZE_PX = (160, 90)  # the top view in the corner, same aspect
INSET_FOG_M = (1.0e4, 2.0e4)  # the top view is far above the level: fog pushed out of the way, m
# Two teams' colours first; a free-for-all's players (a team each) cycle through the rest.
TEAM_RGB = ((0.85, 0.25, 0.2), (0.2, 0.4, 0.9), (0.2, 0.7, 0.3), (0.9, 0.7, 0.1), (0.6, 0.3, 0.8), (0.1, 0.7, 0.8))
LEVEL_RGB = (0.62, 0.6, 0.56)
HIDDEN_OFFSET_M = np.array([0.0, -1.0e4, 0.0])  # where a dead player's capsule is put: out of every view


class VideoUnavailable(RuntimeError):
    """No EGL context (or no video encoder) on this machine: the video is skipped, the run is not."""


def top_view_pose(vertices_world: np.ndarray, lens: Lens) -> CameraPose:
    """A camera straight above the level looking down (screen up = world -Z), high enough that the
    level's whole horizontal extent fits the frame. vertices_world (n, 3) m."""
    low, high = vertices_world.min(axis=0), vertices_world.max(axis=0)
    centre = 0.5 * (low + high)
    half_x, half_z = 0.5 * (high[0] - low[0]), 0.5 * (high[2] - low[2])
    height_m = 1.05 * max(half_z / lens.tan_half_fov_y, half_x / lens.tan_half_fov_x)
    axes = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]).T  # columns: camera x, y, z in the world
    return CameraPose(np.array([centre[0], high[1] + height_m, centre[2]]), matrix_to_quat(axes), lens.vertical_fov_deg)


def _dots(image: np.ndarray, pose: CameraPose, lens: Lens, points_world: np.ndarray, colors: np.ndarray) -> None:
    """Paints 3x3-pixel dots of colors (n, 3) uint8 at points (n, 3) m seen from pose, in place."""
    h, w = image.shape[:2]
    screen = project_to_screen(pose, lens, points_world)
    for (x, y), color in zip(screen, colors):
        if not np.isfinite(x) or abs(x) > 1 or abs(y) > 1:
            continue
        col, row = int((x + 1) * 0.5 * (w - 1)), int((1 - y) * 0.5 * (h - 1))
        image[max(row - 1, 0) : row + 2, max(col - 1, 0) : col + 2] = color


def label_players(
    frame: np.ndarray, match: MatchRecording, index: int, pose: CameraPose, lens: Lens, eyes_of: int = -1
) -> tuple[np.ndarray, list[PlacedLabel]]:
    """The program frame (h, w, 3) uint8 of match frame `index` seen from pose with each living
    player's name label over its head (its feet plus its height), and the labels drawn; none over
    the player in whose eyes the camera is (column eyes_of, -1: none)."""
    alive = match.alive[index].copy()
    if eyes_of >= 0:
        alive[eyes_of] = False
    heads = match.positions_world[index] + np.array([[0.0, p.height_m, 0.0] for p in match.players])
    texts = [(p.name or p.id) if shown else "" for p, shown in zip(match.players, alive.tolist())]
    return draw_labels(frame, pose, lens, heads, texts, _team_rgb8(match))


def _team_rgb8(match: MatchRecording) -> np.ndarray:
    """(P, 3) uint8: each player's team colour."""
    return (255 * np.array(TEAM_RGB)).astype(np.uint8)[[p.team % len(TEAM_RGB) for p in match.players]]


def render_program(match: MatchRecording, program: Program, out_mp4: Path, seconds: float, data_dir: Path | None = None) -> dict:
    """Renders the program's first `seconds` to out_mp4; returns frames, fps and median ms per frame.
    Raises VideoUnavailable when EGL or the encoder cannot start."""
    try:
        from camdirector.geometry.render import OffscreenRenderer
        from camdirector.geometry.video import VideoWriter
    except ImportError as exc:  # moderngl or imageio-ffmpeg missing
        raise VideoUnavailable(str(exc)) from None
    artifact = LevelRegistry(data_dir).load(match.level)
    width, height = VIDEO_SIZE_PX
    lens = Lens(aspect=width / height)
    rows = np.flatnonzero(program.time_s <= program.time_s[0] + seconds)
    fps = float(1.0 / np.median(np.diff(program.time_s))) if len(program) > 1 else 30.0
    top = top_view_pose(artifact.level_vertices, lens)
    team_rgb8 = _team_rgb8(match)
    ids = [p.id for p in match.players]
    eyes = in_eyes_of(match, program)  # (n,) a first-person moment's player: its body is left out, as the game's view
    costs = []
    try:
        # The level does not move: its top view is drawn once, and its GL context released before
        # the program's opens (two live standalone contexts in one thread draw into each other's frames).
        with OffscreenRenderer(*INSET_SIZE_PX, fog_start_m=INSET_FOG_M[0], fog_end_m=INSET_FOG_M[1]) as top_renderer:
            top_renderer.add_mesh("level", artifact.level_vertices, artifact.level_faces, LEVEL_RGB)
            top_image = top_renderer.render(top, lens)
        renderer = OffscreenRenderer(width, height)
    except RuntimeError as exc:
        raise VideoUnavailable(str(exc)) from None
    out_mp4.parent.mkdir(parents=True, exist_ok=True)
    with renderer, VideoWriter(out_mp4, fps, VIDEO_SIZE_PX) as video:
        renderer.add_mesh("level", artifact.level_vertices, artifact.level_faces, LEVEL_RGB, checker_m=1.0)
        for player in match.players:
            body = player_mesh(player)
            renderer.add_mesh(player.id, body.vertices, body.faces, TEAM_RGB[player.team % len(TEAM_RGB)], closed=True)
        for row in rows:
            start = time.perf_counter()
            index = int(program.shown_index[row])  # a replay's picture is of its replayed moment
            alive = match.alive[index]
            drawn = alive.copy()
            if eyes[row] >= 0:
                drawn[eyes[row]] = False
            feet = match.positions_world[index] + np.where(drawn[:, None], 0.0, HIDDEN_OFFSET_M)
            renderer.set_transforms(
                ids, np.stack([RigidTransform(p, q).matrix() for p, q in zip(feet, match.rotations_xyzw[index])])
            )
            inset = top_image.copy()
            _dots(
                inset,
                top,
                lens,
                np.concatenate([match.positions_world[index][alive], program.position[row][None]]),
                np.concatenate([team_rgb8[alive], np.full((1, 3), 255, dtype=np.uint8)]),
            )
            pose = program.pose(int(row))
            frame_lens = Lens(pose.vertical_fov_deg, lens.aspect)  # the program's own width (a widened lens: lens_width.py)
            frame, _ = label_players(renderer.render(pose, frame_lens), match, index, pose, frame_lens, int(eyes[row]))
            frame[: inset.shape[0], width - inset.shape[1] :] = inset
            video.write(frame)
            costs.append((time.perf_counter() - start) * 1e3)
    return {
        "path": str(out_mp4),
        "frames": len(rows),
        "fps": round(fps, 2),
        "size_px": list(VIDEO_SIZE_PX),
        "render_ms_median": round(float(np.median(costs)), 2) if costs else None,
    }
