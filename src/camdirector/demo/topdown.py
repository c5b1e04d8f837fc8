"""Top-down map of a demo run: columns, obstacle tracks, target path, camera path and cuts.

Looking down from +Y in a right-handed, +Y-up world, +X points right and +Z points *down* the
page; the plot keeps that orientation (z axis inverted) so the map is not mirrored against what a
camera above the scene would see.

Uses matplotlib's object API with the Agg canvas, not pyplot, so it keeps no global figure state
and is safe to call from server threads.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Polygon
from scipy.spatial import ConvexHull

from camdirector.demo.scene import DemoScene

_TARGET_COLOR = "#e0601e"  # the avatar's orange
_CAMERA_COLOR = "#1f4e9e"
_COLUMN_COLOR = "#8c8a87"
_TRACK_COLOR = "#3a7f8c"


def draw_topdown(
    scene: DemoScene,
    target_path_xz: np.ndarray,
    camera_path_xz: np.ndarray,
    out_png: str | Path,
    cut_indices: Iterable[int] = (),
) -> Path:
    """Draw the map and write it to out_png; returns the path written.

    target_path_xz: (n, 2) target positions, metres, one per frame. camera_path_xz: (n, 2) camera
    positions, same frames. cut_indices: frames where a new shot starts (camera_path_xz[i] is its
    first position); the jump into it is drawn dotted and the new view is marked.
    """
    target = _as_path(target_path_xz, "target_path_xz")
    camera = _as_path(camera_path_xz, "camera_path_xz")
    cuts = sorted({int(i) for i in cut_indices})
    if cuts and not (0 < cuts[0] and cuts[-1] < len(camera)):
        raise ValueError(f"cut_indices must be in [1, {len(camera) - 1}], got {cuts}")

    fig = Figure(figsize=(8.0, 8.0), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    x_range_m, z_range_m = _limits(target, camera, scene)
    # Metres to points for line widths; the axes are square and so are the limits.
    axes_width_pt = fig.get_figwidth() * ax.get_position().width * 72.0
    points_per_m = axes_width_pt / (x_range_m[1] - x_range_m[0])

    for obj in scene.static_objects:
        if obj.kind == "ground":
            continue
        footprint = obj.transform.apply(obj.vertices)[:, [0, 2]]  # (n, 2) world xz
        hull = footprint[ConvexHull(footprint).vertices]
        ax.add_patch(Polygon(hull, closed=True, facecolor=_COLUMN_COLOR, edgecolor="#555555", linewidth=0.6, zorder=2))

    for track in scene.obstacle_tracks:
        ends = track.endpoints_xz
        # A band as wide as the obstacle: the ground it can occupy at some time.
        ax.plot(
            ends[:, 0],
            ends[:, 1],
            color=_TRACK_COLOR,
            alpha=0.18,
            linewidth=2.0 * track.footprint_radius_m * points_per_m,
            solid_capstyle="round",
            zorder=1,
        )
        ax.plot(ends[:, 0], ends[:, 1], color=_TRACK_COLOR, alpha=0.5, linewidth=0.8, linestyle="--", zorder=1)

    ax.plot(target[:, 0], target[:, 1], color=_TARGET_COLOR, linewidth=2.0, zorder=3)
    # Split the camera path at cuts so a cut does not read as a fast camera move.
    bounds = [0, *cuts, len(camera)]
    for start, stop in zip(bounds[:-1], bounds[1:]):
        ax.plot(camera[start:stop, 0], camera[start:stop, 1], color=_CAMERA_COLOR, linewidth=1.6, zorder=4)
    for i in cuts:
        ax.plot(camera[i - 1 : i + 1, 0], camera[i - 1 : i + 1, 1], color=_CAMERA_COLOR, linewidth=0.8, linestyle=":", zorder=4)
        ax.scatter(camera[i, 0], camera[i, 1], marker="X", s=60, color="#c01f3c", zorder=6)
        if i < len(target):
            sight = np.stack([camera[i], target[i]])
            ax.plot(sight[:, 0], sight[:, 1], color="#c01f3c", linewidth=0.6, alpha=0.6, zorder=5)

    for path, color in ((target, _TARGET_COLOR), (camera, _CAMERA_COLOR)):
        ax.scatter(path[0, 0], path[0, 1], marker="o", s=55, color=color, edgecolor="black", zorder=7)
        ax.scatter(path[-1, 0], path[-1, 1], marker="s", s=55, color=color, edgecolor="black", zorder=7)

    ax.set_xlim(*x_range_m)
    ax.set_ylim(z_range_m[1], z_range_m[0])  # +Z down the page, see module doc
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.grid(True, linewidth=0.3, alpha=0.5)
    ax.legend(
        handles=[
            Line2D([], [], color=_TARGET_COLOR, linewidth=2.0, label="target path"),
            Line2D([], [], color=_CAMERA_COLOR, linewidth=1.6, label="camera path"),
            Line2D([], [], marker="o", linestyle="", color="grey", markeredgecolor="black", label="start"),
            Line2D([], [], marker="s", linestyle="", color="grey", markeredgecolor="black", label="end"),
            Line2D([], [], marker="X", linestyle="", color="#c01f3c", label=f"cut ({len(cuts)}) and new line of sight"),
            Polygon(np.zeros((3, 2)), facecolor=_COLUMN_COLOR, edgecolor="#555555", label="column"),
            Line2D([], [], color=_TRACK_COLOR, alpha=0.4, linewidth=6.0, label="moving obstacle track"),
        ],
        loc="upper right",
        fontsize=8,
        framealpha=0.85,
    )
    ax.set_title(
        f"Demo scene, seed {scene.seed}: {len(scene.column_radii_m)} columns, "
        f"{len(scene.obstacle_tracks)} moving obstacles, {scene.duration_s:.1f} s, "
        f"cuts: {len(cuts)}"
    )
    fig.tight_layout()
    out = Path(out_png)
    fig.savefig(out, format="png")
    return out


def _as_path(path_xz: np.ndarray, name: str) -> np.ndarray:
    path = np.asarray(path_xz, dtype=np.float64)
    if path.ndim != 2 or path.shape[1] != 2 or len(path) == 0:
        raise ValueError(f"{name} must be (n, 2) with n > 0")
    if not np.all(np.isfinite(path)):
        raise ValueError(f"{name} must be finite")
    return path


def _limits(target: np.ndarray, camera: np.ndarray, scene: DemoScene) -> tuple[tuple[float, float], tuple[float, float]]:
    """Square x and z ranges around the paths and obstacle tracks (not the whole ground)."""
    points = np.concatenate([target, camera, *(t.endpoints_xz for t in scene.obstacle_tracks)])
    low, high = points.min(axis=0) - 3.0, points.max(axis=0) + 3.0
    center, half = (low + high) / 2.0, float(np.max(high - low)) / 2.0
    return (center[0] - half, center[0] + half), (center[1] - half, center[1] + half)
