"""Limb visibility descriptor E_limb by rendering coloured ellipsoids (paper Section 3, Figure 7).

"We calculate this descriptor by examining the resulting silhouette of each of six main body parts
(head, torso, two legs and two arms) from various locations. To speed up the calculation we use
character model simplification to a set of ellipsoids, each colored differently. At each render,
the number of pixels in each color indicates the visibility of that silhouette."

Our choices where the paper gives none:

* Only frames whose pose saliency reaches `limb_min_saliency` are rendered: "since such fast
  actions occur in a small number of frames, we can calculate [...] E_limb without requiring huge
  calculation efforts"; in the other frames viewpoint_quality.py uses E_wide in place of the limb
  term, since "otherwise, the widest aspect descriptor on the full body is used".
* One ellipsoid per bone (a joint and its child joint or end site), its long semi-axis half the
  bone plus half the part radius, the other two the part radius (`*_radius_heights`); a bone
  gets the colour of its child's body part. Bones whose length changes over the clip are not
  bones but a root that does not follow the body (Bandai's ``joint_Root`` stays at the origin);
  they are left out, as are bones shorter than 1% of the height.
* "Various locations" are view directions on a sphere around the character:
  `limb_view_azimuths` azimuths times `limb_view_elevations_deg`, rendered orthographically (a far
  camera) so one render per direction serves every candidate distance; potential.py reads a
  candidate position's value by bilinear interpolation in (azimuth, elevation).
* E_limb is "the normalized visibility (in pixels)": per frame and body part, pixel count divided
  by the most pixels that part shows from any direction in that frame (in [0, 1]).

Rendering uses moderngl with EGL (Mesa llvmpipe on CPU machines): every (frame, direction) is one
tile of an atlas; one instanced draw call renders a whole atlas, one read gives every count.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from camdirector.geometry.transforms import UP_WORLD
from camdirector.precompute.overview.body_parts import PART_COUNT, BodyPartMap, rigid_bones
from camdirector.precompute.overview.bvh import MotionClip
from camdirector.precompute.overview.character_track import CharacterTrack
from camdirector.precompute.overview.overview_settings import OverviewSettings

_ATLAS_MAX_PX = 2048  # atlas side, pixels (llvmpipe handles 2048^2 in one pass)
_MIN_BONE_HEIGHTS = 0.01  # bones shorter than this (heights) are left out

_VERTEX_SHADER = """
#version 330
in vec3 in_vertex;
in vec3 in_axis_x;
in vec3 in_axis_y;
in vec3 in_axis_z;
in vec3 in_offset;
in vec2 in_tile;
in float in_colour;
uniform vec2 tiles;
flat out float colour;
void main() {
    vec3 v = mat3(in_axis_x, in_axis_y, in_axis_z) * in_vertex + in_offset;
    vec2 xy = -1.0 + (2.0 * in_tile + v.xy + 1.0) / tiles;
    gl_Position = vec4(xy, -v.z * 0.5, 1.0);
    colour = in_colour;
}
"""
_FRAGMENT_SHADER = """
#version 330
flat in float colour;
out float out_colour;
void main() { out_colour = colour / 255.0; }
"""


@dataclass(frozen=True)
class LimbVisibility:
    """pixels: (R, 6, n_el, n_az) float pixel counts per rendered frame, body part (BodyPart order),
    elevation and azimuth; normalised: the same divided by each (frame, part)'s maximum, in [0, 1];
    row_of_frame: (T,) int row of each track frame in those arrays, -1 where not rendered;
    azimuths_rad: (n_az,) measured about +Y from +Z toward +X; elevations_rad: (n_el,)."""

    row_of_frame: np.ndarray
    pixels: np.ndarray
    normalised: np.ndarray
    azimuths_rad: np.ndarray
    elevations_rad: np.ndarray


def view_directions(azimuths_rad: np.ndarray, elevations_rad: np.ndarray) -> np.ndarray:
    """(n_el, n_az, 3) unit vectors from the character toward the camera."""
    az, el = np.meshgrid(azimuths_rad, elevations_rad)
    return np.stack([np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az)], axis=-1)


def _unit_sphere(subdivisions: int = 0) -> np.ndarray:
    """(n, 3) float32 triangle-list vertices of an icosphere: an icosahedron (20 triangles) at 0
    subdivisions, 80 at 1. The icosahedron is the default: llvmpipe's cost is per triangle, and at
    a few pixels per bone the shape error (the icosahedron's inradius is 0.79) is below a pixel."""
    t = (1.0 + math.sqrt(5.0)) / 2.0
    verts = [
        (-1, t, 0),
        (1, t, 0),
        (-1, -t, 0),
        (1, -t, 0),
        (0, -1, t),
        (0, 1, t),
        (0, -1, -t),
        (0, 1, -t),
        (t, 0, -1),
        (t, 0, 1),
        (-t, 0, -1),
        (-t, 0, 1),
    ]
    faces = [
        (0, 11, 5),
        (0, 5, 1),
        (0, 1, 7),
        (0, 7, 10),
        (0, 10, 11),
        (1, 5, 9),
        (5, 11, 4),
        (11, 10, 2),
        (10, 7, 6),
        (7, 1, 8),
        (3, 9, 4),
        (3, 4, 2),
        (3, 2, 6),
        (3, 6, 8),
        (3, 8, 9),
        (4, 9, 5),
        (2, 4, 11),
        (6, 2, 10),
        (8, 6, 7),
        (9, 8, 1),
    ]
    tris = np.array([[verts[i] for i in f] for f in faces], dtype=np.float64)
    tris /= np.linalg.norm(tris, axis=2, keepdims=True)
    for _ in range(subdivisions):
        a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
        ab, bc, ca = [(p + q) / np.linalg.norm(p + q, axis=1, keepdims=True) for p, q in ((a, b), (b, c), (c, a))]
        tris = np.concatenate([np.stack(x, axis=1) for x in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    return tris.reshape(-1, 3).astype(np.float32)


def _bones(
    clip: MotionClip, parts: BodyPartMap, settings: OverviewSettings, height_m: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Ellipsoid bones: parent and child point indices (into `MotionClip.all_points_m`), body part
    (B,) of the child (of the parent for an end site), radius_m (B,)."""
    parent, child = rigid_bones(clip)
    n_joints = len(clip.joint_names)
    owner = np.where(child < n_joints, child, parent)
    part = parts.part_of_joint[owner]
    radius_of = (
        np.array(
            [
                settings.head_radius_heights,
                settings.torso_radius_heights,
                settings.arm_radius_heights,
                settings.arm_radius_heights,
                settings.leg_radius_heights,
                settings.leg_radius_heights,
            ]
        )
        * height_m
    )
    points = clip.all_points_m
    length = np.linalg.norm(points[:, child] - points[:, parent], axis=2).mean(axis=0)
    keep = length >= _MIN_BONE_HEIGHTS * height_m
    if not np.any(keep):
        raise ValueError("the skeleton has no rigid bone to build ellipsoids from")
    return parent[keep], child[keep], part[keep], radius_of[part[keep]]


class LimbVisibilityRenderer:
    """Renders ellipsoid characters offscreen and counts pixels per body part.

    Owns a moderngl EGL context; call `release()` when done (or use it as a context manager)."""

    def __init__(self, tile_px: int):
        from camdirector.geometry.gl_context import egl_context, uniform  # deferred: only this stage needs OpenGL

        self.tile_px = int(tile_px)
        self.tiles_per_side = max(1, _ATLAS_MAX_PX // self.tile_px)
        side = self.tiles_per_side * self.tile_px
        self._ctx = egl_context()
        self._program = self._ctx.program(vertex_shader=_VERTEX_SHADER, fragment_shader=_FRAGMENT_SHADER)
        uniform(self._program, "tiles").value = (float(self.tiles_per_side), float(self.tiles_per_side))
        self._sphere = self._ctx.buffer(_unit_sphere().tobytes())
        self._colour_rb = self._ctx.renderbuffer((side, side), components=1, dtype="f1")
        self._depth_rb = self._ctx.depth_renderbuffer((side, side))
        self._fbo = self._ctx.framebuffer(color_attachments=[self._colour_rb], depth_attachment=self._depth_rb)
        self._side = side

    def __enter__(self) -> LimbVisibilityRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    def release(self) -> None:
        self._ctx.release()

    def count_pixels(self, instances: np.ndarray, tile_count: int) -> np.ndarray:
        """Render (N, 15) float32 instances (3 axis columns, offset, tile xy, colour id 1..6) over
        `tile_count` tiles of one atlas; (tile_count, 7) pixel counts per colour id (0 = empty)."""
        ctx = self._ctx
        inst = ctx.buffer(np.ascontiguousarray(instances, dtype=np.float32).tobytes())
        vao = ctx.vertex_array(
            self._program,
            [
                (self._sphere, "3f", "in_vertex"),
                (inst, "3f 3f 3f 3f 2f 1f/i", "in_axis_x", "in_axis_y", "in_axis_z", "in_offset", "in_tile", "in_colour"),
            ],
        )
        self._fbo.use()
        ctx.enable(ctx.DEPTH_TEST)
        self._fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        vao.render(instances=len(instances))
        raw = np.frombuffer(self._fbo.read(components=1, dtype="f1"), dtype=np.uint8)
        vao.release()
        inst.release()
        n, px = self.tiles_per_side, self.tile_px
        image = raw.reshape(n, px, n, px)  # (tile row, y, tile col, x)
        tile_of_pixel = np.arange(n)[:, None, None, None] * n + np.arange(n)[None, None, :, None]
        tile_of_pixel = np.broadcast_to(tile_of_pixel, image.shape)
        keys = tile_of_pixel.astype(np.int64) * 8 + image
        counts = np.bincount(keys.ravel(), minlength=n * n * 8).reshape(n * n, 8)
        return counts[:tile_count, :7]


def render_limb_visibility(
    clip: MotionClip,
    parts: BodyPartMap,
    track: CharacterTrack,
    pose_saliency: np.ndarray,
    settings: OverviewSettings,
    renderer: LimbVisibilityRenderer,
) -> LimbVisibility:
    """E_limb per track frame with pose saliency (T,) at least `limb_min_saliency`, per body part
    and view direction (see the module docstring)."""
    selected = np.flatnonzero(pose_saliency >= settings.limb_min_saliency)
    row_of_frame = np.full(track.frame_count, -1, dtype=np.int64)
    row_of_frame[selected] = np.arange(len(selected))
    azimuths = np.linspace(0.0, 2.0 * np.pi, settings.limb_view_azimuths, endpoint=False)
    elevations = np.radians(np.asarray(settings.limb_view_elevations_deg, dtype=np.float64))
    dirs = view_directions(azimuths, elevations).reshape(-1, 3)  # (V, 3) back axis
    right = np.cross(UP_WORLD, dirs)
    right /= np.linalg.norm(right, axis=1, keepdims=True)
    cam_up = np.cross(dirs, right)
    view = np.stack([right, cam_up, dirs], axis=1)  # (V, 3, 3) rows
    parent, child, part, radius = _bones(clip, parts, settings, track.height_m)
    points = clip.all_points_m[track.frame_indices[selected]]  # (R, P, 3)
    a, b = points[:, parent], points[:, child]  # (T, B, 3)
    centre = 0.5 * (a + b)
    axis = b - a
    length = np.linalg.norm(axis, axis=2, keepdims=True)
    u = axis / np.maximum(length, 1e-9)
    helper = np.where(np.abs(u[..., 1:2]) < 0.9, UP_WORLD, np.array([1.0, 0.0, 0.0]))
    v = np.cross(u, helper)
    v /= np.linalg.norm(v, axis=2, keepdims=True)
    w = np.cross(u, v)
    semi_long = 0.5 * length + 0.5 * radius[None, :, None]
    axes = np.stack([u * semi_long, v * radius[None, :, None], w * radius[None, :, None]], axis=2)  # (T, B, 3 axes, 3)
    extent = track.radius_m[selected]  # (R,)
    rel_centre = (centre - track.look_at_m[selected][:, None]) / extent[:, None, None]
    axes = axes / extent[:, None, None, None]
    n_frames, n_bones, n_views = len(points), len(parent), len(dirs)
    tiles_per_atlas = renderer.tiles_per_side**2
    pixels = np.zeros((n_frames * n_views, PART_COUNT))
    colour = (part + 1).astype(np.float32)
    # Flattened (frame, view) tile order; each atlas takes the next tiles_per_atlas of them.
    for first in range(0, n_frames * n_views, tiles_per_atlas):
        ids = np.arange(first, min(first + tiles_per_atlas, n_frames * n_views))
        f, vw = ids // n_views, ids % n_views
        rot = view[vw]  # (K, 3, 3)
        ax = np.einsum("kij,kbaj->kbai", rot, axes[f])  # (K, B, 3, 3)
        off = np.einsum("kij,kbj->kbi", rot, rel_centre[f])  # (K, B, 3)
        local = np.arange(len(ids))
        tile_xy = np.stack([local % renderer.tiles_per_side, local // renderer.tiles_per_side], axis=1).astype(np.float32)
        inst = np.concatenate(
            [
                ax.reshape(len(ids), n_bones, 9),
                off,
                np.broadcast_to(tile_xy[:, None], (len(ids), n_bones, 2)),
                np.broadcast_to(colour[None, :, None], (len(ids), n_bones, 1)),
            ],
            axis=2,
        ).reshape(-1, 15)
        counts = renderer.count_pixels(inst, len(ids))
        pixels[ids] = counts[:, 1 : PART_COUNT + 1]
    per_view = pixels.reshape(n_frames, len(elevations), len(azimuths), PART_COUNT).transpose(0, 3, 1, 2)
    best = per_view.max(axis=(2, 3), keepdims=True)
    normalised = np.where(best > 0, per_view / np.maximum(best, 1.0), 0.0)
    return LimbVisibility(
        row_of_frame=row_of_frame, pixels=per_view, normalised=normalised, azimuths_rad=azimuths, elevations_rad=elevations
    )
