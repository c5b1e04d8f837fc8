"""The viewpoint potential space: V over candidate camera positions and frames (paper Section 3,
"the viewpoint potential space, which describes the viewpoint quality for each point in
space-time"; Figure 5 shows a horizontal slice "at the mid height of the space cube").

Candidate positions are a regular grid (our choice of layout): horizontally every
`grid_spacing_heights` over the character's look-at path grown by `grid_margin_heights`, and at
the heights `camera_heights_heights` above the clip's floor. V between grid nodes is trilinear.

A position is *allowed* at a frame when it is inside the grid box, outside the character's
bounding box grown by `clearance_heights`, and far enough from the look-at point that a sphere
holding the whole body fits a lens of `max_vertical_fov_deg` with `frame_margin` to spare
(d >= r / sin(atan(tan(fov_max / 2) * (1 - margin)))). Those two distance rules are what keep every
joint inside the frame and the camera out of the character in the result.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from camdirector.precompute.overview.body_parts import BodyPartMap
from camdirector.precompute.overview.character_track import CharacterTrack
from camdirector.precompute.overview.limb_visibility import LimbVisibility
from camdirector.precompute.overview.overview_settings import OverviewSettings
from camdirector.precompute.overview.saliency import Saliency
from camdirector.precompute.overview.viewpoint_quality import scene_visibility, viewpoint_quality

_FRAMES_PER_CHUNK = 64  # frames evaluated at once (bounds memory to chunk * positions floats)


@dataclass(frozen=True)
class PotentialSpace:
    """xs (nx,), ys (ny,), zs (nz,): grid axes, metres; values: (T, nx, ny, nz) float32 V;
    allowed: (T, nx, ny, nz) bool; best: (T,) max of V over allowed nodes (Q's denominator);
    min_distance_m: (T,) closest allowed distance from the look-at point; box_clearance_m: gap
    kept around the character's bounding box."""

    xs: np.ndarray
    ys: np.ndarray
    zs: np.ndarray
    values: np.ndarray
    allowed: np.ndarray
    best: np.ndarray
    min_distance_m: np.ndarray
    box_clearance_m: float

    @property
    def shape(self) -> tuple[int, int, int]:
        return len(self.xs), len(self.ys), len(self.zs)

    def positions(self) -> np.ndarray:
        """(nx * ny * nz, 3) node positions, x slowest, z fastest (matches values' flat order)."""
        gx, gy, gz = np.meshgrid(self.xs, self.ys, self.zs, indexing="ij")
        return np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1)

    def lower(self) -> np.ndarray:
        return np.array([self.xs[0], self.ys[0], self.zs[0]])

    def upper(self) -> np.ndarray:
        return np.array([self.xs[-1], self.ys[-1], self.zs[-1]])

    def sample(self, frames: np.ndarray, positions_m: np.ndarray) -> np.ndarray:
        """(n,) V at (n,) track frames and (n, 3) positions, trilinear (clamped to the grid)."""
        idx, weights = [], []
        for axis, nodes in enumerate((self.xs, self.ys, self.zs)):
            f = np.interp(positions_m[:, axis], nodes, np.arange(len(nodes)))
            i0 = np.minimum(np.floor(f).astype(np.int64), len(nodes) - 2)
            idx.append(i0)
            weights.append(f - i0)
        (ix, iy, iz), (wx, wy, wz) = idx, weights
        v = self.values
        out = np.zeros(len(frames))
        for dx in (0, 1):
            for dy in (0, 1):
                for dz in (0, 1):
                    w = (wx if dx else 1 - wx) * (wy if dy else 1 - wy) * (wz if dz else 1 - wz)
                    out += w * v[frames, ix + dx, iy + dy, iz + dz]
        return out


def closest_distance_m(track: CharacterTrack, settings: OverviewSettings) -> np.ndarray:
    """(T,) the closest camera distance from the look-at point that frames the whole body."""
    half = math.atan(math.tan(math.radians(settings.max_vertical_fov_deg) / 2.0) * (1.0 - settings.frame_margin))
    return track.radius_m / math.sin(half)


def allowed_positions(track: CharacterTrack, space: PotentialSpace, frames: np.ndarray, positions_m: np.ndarray) -> np.ndarray:
    """bool of shape broadcast(frames.shape, positions_m.shape[:-1]): positions (..., 3) allowed
    at track frames (...) (see the module docstring). Frames (n,) with positions (n, 3) test
    pairs; frames (T, 1) with positions (P, 3) test every pair (T, P)."""
    inside_grid = np.all((positions_m >= space.lower() - 1e-9) & (positions_m <= space.upper() + 1e-9), axis=-1)
    far = np.linalg.norm(positions_m - track.look_at_m[frames], axis=-1) >= space.min_distance_m[frames]
    c = space.box_clearance_m
    in_box = np.all((positions_m >= track.box_min_m[frames] - c) & (positions_m <= track.box_max_m[frames] + c), axis=-1)
    return inside_grid & far & ~in_box


def build_potential_space(
    track: CharacterTrack, parts: BodyPartMap, saliency: Saliency, limbs: LimbVisibility, settings: OverviewSettings, scene=None
) -> PotentialSpace:
    """V over the candidate grid at every track frame; `scene`: optional static trimesh.Trimesh."""
    h = track.height_m
    margin = settings.grid_margin_heights * h
    spacing = settings.grid_spacing_heights * h
    lo = track.look_at_m.min(axis=0) - margin
    hi = track.look_at_m.max(axis=0) + margin
    xs = np.arange(lo[0], hi[0] + 0.5 * spacing, spacing)
    zs = np.arange(lo[2], hi[2] + 0.5 * spacing, spacing)
    ys = track.floor_y_m + np.asarray(settings.camera_heights_heights) * h
    shape = (len(xs), len(ys), len(zs))
    gx, gy, gz = np.meshgrid(xs, ys, zs, indexing="ij")
    nodes = np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1)
    n_frames = track.frame_count
    visibility = None if scene is None else scene_visibility(track, parts, nodes, scene, settings)
    values = np.empty((n_frames, len(nodes)), dtype=np.float32)
    for first in range(0, n_frames, _FRAMES_PER_CHUNK):
        frames = np.arange(first, min(first + _FRAMES_PER_CHUNK, n_frames))
        values[frames] = viewpoint_quality(track, frames, nodes, saliency, limbs, settings, visibility)
    space = PotentialSpace(
        xs=xs,
        ys=ys,
        zs=zs,
        values=values.reshape((n_frames,) + shape),
        allowed=np.zeros((n_frames,) + shape, dtype=bool),
        best=np.zeros(n_frames),
        min_distance_m=closest_distance_m(track, settings),
        box_clearance_m=settings.clearance_heights * h,
    )
    allowed = np.empty((n_frames, len(nodes)), dtype=bool)
    for first in range(0, n_frames, _FRAMES_PER_CHUNK):
        frames = np.arange(first, min(first + _FRAMES_PER_CHUNK, n_frames))
        allowed[frames] = allowed_positions(track, space, frames[:, None], nodes)
    if not np.all(allowed.any(axis=1)):
        raise ValueError(
            "no candidate camera position frames the character in some frame: raise grid_margin_heights or max_vertical_fov_deg"
        )
    best = np.where(allowed, values, -np.inf).max(axis=1)
    return PotentialSpace(
        xs=xs,
        ys=ys,
        zs=zs,
        values=space.values,
        allowed=allowed.reshape((n_frames,) + shape),
        best=best,
        min_distance_m=space.min_distance_m,
        box_clearance_m=space.box_clearance_m,
    )
