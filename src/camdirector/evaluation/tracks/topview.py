"""Top views (x right, z down the page, +Y towards the viewer) of a level's navmesh, skeleton,
camera tracks, graphs and routes, with matplotlib's Agg backend (no display needed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def draw_graph_panel(
    ax,
    navmesh_vertices: np.ndarray,
    navmesh_faces: np.ndarray,
    nodes_world: np.ndarray,
    edges: np.ndarray,
    title: str,
    *,
    skeleton_segments: np.ndarray | None = None,
    route_world: np.ndarray | None = None,
    camera_world: np.ndarray | None = None,
) -> None:
    """One panel: navmesh (light blue), skeleton (red), graph edges (dark) and nodes, the actor's
    route (cyan) and the camera's path (green). Arrays in metres, world frame."""
    from matplotlib.collections import LineCollection, PolyCollection

    ax.add_collection(PolyCollection(navmesh_vertices[navmesh_faces][:, :, [0, 2]], facecolor="#cfe8f3", edgecolor="none"))
    if skeleton_segments is not None and len(skeleton_segments):
        ax.add_collection(LineCollection(list(skeleton_segments[:, :, [0, 2]]), colors="#d62728", linewidths=0.5))
    if len(edges):
        ax.add_collection(LineCollection(nodes_world[edges][:, :, [0, 2]], colors="#333333", linewidths=0.4))
    ax.plot(nodes_world[:, 0], nodes_world[:, 2], ".", color="#1f3b73", markersize=1.5)
    if route_world is not None:
        ax.plot(route_world[:, 0], route_world[:, 2], "-", color="#17becf", linewidth=1.5)
    if camera_world is not None:
        ax.plot(camera_world[:, 0], camera_world[:, 2], "-", color="#2ca02c", linewidth=1.0)
    ax.set_title(title, fontsize=9)
    ax.set_aspect("equal")
    ax.autoscale()
    ax.invert_yaxis()


def save_panels(path: Path, panels: list[dict], columns: int = 2) -> None:
    """Draw `draw_graph_panel(**panel)` for each panel dict into one PNG at path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = (len(panels) + columns - 1) // columns
    fig, axes = plt.subplots(rows, columns, figsize=(7 * columns, 7 * rows), squeeze=False)
    for ax, panel in zip(axes.flat, panels):
        draw_graph_panel(ax, **panel)
    for ax in list(axes.flat)[len(panels) :]:
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
