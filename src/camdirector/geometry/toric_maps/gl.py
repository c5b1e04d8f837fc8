"""S-maps and V-maps by deferred projection with OpenGL through EGL (moderngl): the paper's method.

Paper: occlusion-anticipation-toric-space.md section 4.1. Two passes per call, for all k sample
points at once:

1. Occluder pass (shadow-map style). One instanced draw, instance i = sample i: every occluder is
   seen from sample point s_i through a frustum fitted to the window's patch of the torus, into tile
   i of an atlas. Each fragment stores its linear distance to s_i (also written as its depth, so
   the nearest occluder wins with 24-bit precision over the whole range) and its world velocity
   v + w x (p - c), computed per vertex from the object's pose and velocity: rigid-motion velocity
   is affine in p, so interpolation is exact. This is the paper's Z_occ and dP_occ/dt.
2. Toric surface pass. One draw over an atlas of k tiles of res x res texels in texture space: the
   window's (theta, phi) quad is the surface mesh, its texture coordinates are the Toric angles, and
   each fragment evaluates the torus position P(theta, phi), its tangents (T, B of the TBN) and the
   torus velocity exactly (closed form of geometry/toric.py), so the map texels sit on the same
   points as the ray-cast backend's. P is projected into tile i, Z_occ is fetched and compared with
   |P - s_i| (section 4.1.1); where occluded, (v_occ - v_toric) is projected on T and B and divided by
   their lengths (section 4.1.2): Toric angular rates, rad/s.

The paper renders the torus mesh from s and scatters it to texture space through a UV buffer; we
gather in texture space instead (every texel gets exactly one answer, no holes).

Per call: uniforms, one small texture write (object poses and velocities), two draws, one readback.
Vertex data is uploaded when the scene's geometry changes, not per call. One EGL context per
thread, shared by the thread's backends (`_thread_context`), made current around every call
(another context may be current in the thread); `close()` releases a backend's own GL objects.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypedDict

import moderngl
import numpy as np
import numpy.typing as npt

from camdirector.geometry.gl_context import egl_context, uniform
from camdirector.geometry.toric import Torus, torus_position
from camdirector.geometry.toric_maps.base import (
    NOT_OCCLUDED_DEPTH,
    SAMPLE_CLEARANCE_M,
    SEGMENT_END_MARGIN,
    MapWindow,
    OccluderScene,
    ShadowVelocityMaps,
    check_compute_args,
)
from camdirector.geometry.transforms import quat_to_matrix

MAX_SAMPLES = 32  # sample points per call: size of the shaders' uniform arrays
_GL_CLIP_DISTANCE0 = 0x3000
_NO_OCCLUDER_DISTANCE = 1e30  # clear value of the occluder atlas's distance channel
_THREAD = threading.local()  # .ctx: the thread's EGL context (_thread_context)


def _thread_context() -> moderngl.Context:
    """The calling thread's EGL context, made on first use and kept for the thread's life: every
    backend of the thread (every map-mode session of a worker process) shares it, each with its
    own buffers, framebuffers and programs. A context is current on one thread at a time, hence
    one per thread rather than per process.

    Measured on the 2-core CPU machine (Mesa llvmpipe, 300 make-use-release cycles): a context
    per backend costs 8.5 ms to make and, even released (with or without malloc_trim), leaves
    about 0.05 MB behind in the driver every time (12-16 MB per 300, not levelling off); a shared
    one costs 0.1 ms and stops growing after its first use (4 MB)."""
    ctx: moderngl.Context | None = getattr(_THREAD, "ctx", None)
    if ctx is None:
        try:
            ctx = egl_context()
        except Exception as err:  # EGL missing or no usable driver: say which call failed
            raise RuntimeError(f"GLMapBackend: no EGL GL context ({err})") from err
        _THREAD.ctx = ctx
    return ctx


class GLMapSettingsArgs(TypedDict, total=False):
    """GLMapSettings' fields as keyword arguments (toric_maps.make_backend passes them on)."""

    shadow_map_scale: float
    max_shadow_map_px: int
    frustum_margin: float
    max_half_angle_deg: float


@dataclass(frozen=True)
class GLMapSettings:
    shadow_map_scale: float = 2.0  # occluder-pass pixels per map texel, per side. [0.5, 8]
    max_shadow_map_px: int = 2048  # cap on one occluder tile's side, px. [16, 8192]
    frustum_margin: float = 0.02  # widening of each fitted frustum, fraction of its extent. [0, 0.5]
    max_half_angle_deg: float = 80.0  # widest frustum half-angle; texels seen beyond it read "not occluded", deg. [10, 85]

    def __post_init__(self) -> None:
        checks = [
            (0.5 <= self.shadow_map_scale <= 8.0, "shadow_map_scale must be in [0.5, 8]"),
            (16 <= self.max_shadow_map_px <= 8192, "max_shadow_map_px must be in [16, 8192]"),
            (0.0 <= self.frustum_margin <= 0.5, "frustum_margin must be in [0, 0.5]"),
            (10.0 <= self.max_half_angle_deg <= 85.0, "max_half_angle_deg must be in [10, 85]"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(f"GLMapSettings: {message}")


_OCCLUDER_VS = f"""
#version 330
#define MAX_K {MAX_SAMPLES}
uniform sampler2D u_objects;         // (5, objects): model rows 0-2 (w = translation), v, w
uniform mat4 u_view_proj[MAX_K];     // clip from (world - eye)
uniform vec3 u_eye[MAX_K];
uniform int u_exclude[MAX_K];        // object index each sample ignores, -1 none
uniform ivec2 u_tiles;               // atlas columns, rows
in vec3 in_position;
in float in_object;
out vec3 v_rel;
out vec3 v_velocity;
out float gl_ClipDistance[4];
void main() {{
    int obj = int(in_object + 0.5);
    int i = gl_InstanceID;
    vec4 r0 = texelFetch(u_objects, ivec2(0, obj), 0);
    vec4 r1 = texelFetch(u_objects, ivec2(1, obj), 0);
    vec4 r2 = texelFetch(u_objects, ivec2(2, obj), 0);
    vec3 lin = texelFetch(u_objects, ivec2(3, obj), 0).xyz;
    vec3 ang = texelFetch(u_objects, ivec2(4, obj), 0).xyz;
    vec4 p = vec4(in_position, 1.0);
    vec3 world = vec3(dot(r0, p), dot(r1, p), dot(r2, p));
    v_velocity = lin + cross(ang, world - vec3(r0.w, r1.w, r2.w));
    v_rel = world - u_eye[i];
    vec4 clip = u_view_proj[i] * vec4(v_rel, 1.0);
    // Keep the sample's frustum only, then move it into tile i of the atlas.
    float keep = (obj == u_exclude[i]) ? -1.0 : 1.0;
    gl_ClipDistance[0] = keep * (clip.w + clip.x);
    gl_ClipDistance[1] = keep * (clip.w - clip.x);
    gl_ClipDistance[2] = keep * (clip.w + clip.y);
    gl_ClipDistance[3] = keep * (clip.w - clip.y);
    vec2 scale = 1.0 / vec2(u_tiles);
    vec2 tile = vec2(i % u_tiles.x, i / u_tiles.x);
    clip.xy = (clip.xy + clip.w) * scale + (2.0 * tile * scale - 1.0) * clip.w;
    gl_Position = clip;
}}
"""

_OCCLUDER_FS = """
#version 330
uniform float u_inv_far;
in vec3 v_rel;
in vec3 v_velocity;
out vec4 f_out;
void main() {
    float d = length(v_rel);
    gl_FragDepth = clamp(d * u_inv_far, 0.0, 1.0);   // linear depth: uniform precision, nearest wins
    f_out = vec4(d, v_velocity);
}
"""

_TORIC_VS = """
#version 330
in vec2 in_ndc;
void main() { gl_Position = vec4(in_ndc, 0.0, 1.0); }
"""

_TORIC_FS = f"""
#version 330
#define MAX_K {MAX_SAMPLES}
uniform sampler2D u_occ;
uniform int u_res;
uniform int u_shadow_px;
uniform int u_count;
uniform ivec2 u_tiles;
uniform vec4 u_window;                // theta_min, phi_min, theta_step, phi_step (rad)
uniform vec3 u_torus;                 // alpha, arc radius, centre offset
uniform mat3 u_basis;                 // columns axis, ref, side: world offset = u_basis * local
uniform vec3 u_prev_torus;
uniform mat3 u_prev_basis;
uniform vec3 u_mid_shift;             // mid now - mid before, m
uniform float u_inv_dt;               // 0: torus taken as still
uniform float u_keep;                 // 1 - SEGMENT_END_MARGIN
uniform mat4 u_view_proj[MAX_K];
uniform vec3 u_mid_from_eye[MAX_K];   // torus midpoint - sample point, m
out vec4 f_out;

vec3 torus_local(vec3 tor, float theta, float phi) {{
    float t = tor.x + theta;
    float radial = tor.z - tor.y * cos(t);
    return vec3(-tor.y * sin(t), radial * cos(phi), radial * sin(phi));
}}

void main() {{
    ivec2 px = ivec2(gl_FragCoord.xy);
    ivec2 tile = px / u_res;
    int i = tile.y * u_tiles.x + tile.x;
    f_out = vec4(0.0, 0.0, 0.0, -1.0);
    if (i >= u_count) return;
    ivec2 texel = px - tile * u_res;                  // x: phi column j, y: theta row i
    float theta = u_window.x + (float(texel.y) + 0.5) * u_window.z;
    float phi = u_window.y + (float(texel.x) + 0.5) * u_window.w;
    vec3 local = torus_local(u_torus, theta, phi);
    vec3 rel = u_mid_from_eye[i] + u_basis * local;   // P - s_i
    float dist = length(rel);
    vec4 clip = u_view_proj[i] * vec4(rel, 1.0);
    if (clip.w <= 0.0) return;
    vec2 ndc = clip.xy / clip.w;
    if (abs(ndc.x) > 1.0 || abs(ndc.y) > 1.0) return;
    ivec2 sp = clamp(ivec2((ndc * 0.5 + 0.5) * float(u_shadow_px)), ivec2(0), ivec2(u_shadow_px - 1));
    vec4 occ = texelFetch(u_occ, tile * u_shadow_px + sp, 0);
    if (!(occ.x < dist * u_keep)) return;
    // Torus point velocity by finite difference at fixed (theta, phi); relative occluder velocity.
    vec3 prev_local = torus_local(u_prev_torus, theta, phi);
    vec3 v_toric = (u_mid_shift + u_basis * local - u_prev_basis * prev_local) * u_inv_dt;
    vec3 dv = occ.yzw - v_toric;
    float t = u_torus.x + theta;
    float s = sin(t), c = cos(t), sp_ = sin(phi), cp = cos(phi);
    float radial = u_torus.z - u_torus.y * c;
    vec3 d_theta = u_basis * vec3(-u_torus.y * c, u_torus.y * s * cp, u_torus.y * s * sp_);
    vec3 d_phi = u_basis * vec3(0.0, -radial * sp_, radial * cp);
    float n_phi = dot(d_phi, d_phi);
    float v_phi = n_phi > 1e-18 ? dot(dv, d_phi) / n_phi : 0.0;
    f_out = vec4(1.0, dot(dv, d_theta) / dot(d_theta, d_theta), v_phi, occ.x);
}}
"""


def _mat4_bytes(matrices: npt.NDArray[np.float64], length: int) -> bytes:
    """(n, 4, 4) row-major -> GLSL mat4[length] (column-major), zero padded."""
    out = np.zeros((length, 4, 4), dtype="f4")
    out[: len(matrices)] = np.transpose(matrices, (0, 2, 1))
    return out.tobytes()


def _vec3_bytes(vectors: npt.NDArray[np.float64], length: int) -> bytes:
    out = np.zeros((length, 3), dtype="f4")
    out[: len(vectors)] = vectors
    return out.tobytes()


# One atlas set (GLMapBackend._target_for): tile columns and rows, occluder tile side px, the
# occluder texture and framebuffer, the output texture and framebuffer, and the readback array.
_Atlases = tuple[
    int, int, int, moderngl.Texture, moderngl.Framebuffer, moderngl.Texture, moderngl.Framebuffer, npt.NDArray[np.float32]
]


class GLMapBackend:
    """MapBackend by deferred projection (EGL: Mesa llvmpipe without a GPU, the GPU where there is one).

    Use as a context manager or call close(): it owns GL objects in its thread's context.
    """

    name = "gl"

    def __init__(self, scene: OccluderScene, settings: GLMapSettings = GLMapSettings()):
        self.scene = scene
        self.settings = settings
        ctx = _thread_context()
        self._ctx: moderngl.Context | None = ctx
        self.renderer = str(ctx.info.get("GL_RENDERER", ""))
        with ctx:
            self._occ_prog = ctx.program(vertex_shader=_OCCLUDER_VS, fragment_shader=_OCCLUDER_FS)
            self._toric_prog = ctx.program(vertex_shader=_TORIC_VS, fragment_shader=_TORIC_FS)
            uniform(self._occ_prog, "u_objects").value = 1
            uniform(self._toric_prog, "u_occ").value = 0
            quad = np.array([-1, -1, 1, -1, -1, 1, -1, 1, 1, -1, 1, 1], dtype="f4")
            self._quad_vbo = ctx.buffer(quad.tobytes())
            self._quad_vao = ctx.vertex_array(self._toric_prog, [(self._quad_vbo, "2f", "in_ndc")])
        self._version = -1
        self._scene_vao: moderngl.VertexArray | None = None
        self._scene_buffers: list[moderngl.Buffer] = []
        self._objects_tex: moderngl.Texture | None = None
        self._object_index: dict[str, int] = {}
        self._targets: dict[tuple[int, int, int], _Atlases] = {}  # atlases by (samples, resolution, tile px)

    def __reduce__(self) -> tuple[type[GLMapBackend], tuple[OccluderScene, GLMapSettings]]:
        """Pickled as its scene and settings: unpickling makes its GL objects again, in the
        unpickling thread's context (nothing drawn is kept between two computes)."""
        return GLMapBackend, (self.scene, self.settings)

    # -- resources -----------------------------------------------------------------------------

    def _sync_scene(self, ctx: moderngl.Context) -> None:
        if self._version == self.scene.geometry_version:
            return
        if self._scene_vao is not None:
            self._scene_vao.release()
        for buf in self._scene_buffers:
            buf.release()
        self._scene_vao, self._scene_buffers = None, []
        parts, faces, base = [], [], 0
        meshes = [(m.vertices, m.faces, 0) for m in self.scene.static_meshes_world]
        self._object_index = {}
        for index, (object_id, obj) in enumerate(self.scene.dynamic.items(), start=1):
            self._object_index[object_id] = index
            meshes.append((obj.mesh_local.vertices, obj.mesh_local.faces, index))
        for vertices, tri, index in meshes:
            part = np.empty((len(vertices), 4), dtype="f4")
            part[:, :3] = vertices
            part[:, 3] = index
            parts.append(part)
            faces.append(tri.astype("i4") + base)
            base += len(vertices)
        if parts:
            vbo = ctx.buffer(np.concatenate(parts).tobytes())
            ibo = ctx.buffer(np.concatenate(faces).tobytes())
            self._scene_vao = ctx.vertex_array(
                self._occ_prog, [(vbo, "3f 1f", "in_position", "in_object")], index_buffer=ibo, index_element_size=4
            )
            self._scene_buffers = [vbo, ibo]
        if self._objects_tex is not None:
            self._objects_tex.release()
        self._objects_tex = ctx.texture((5, len(self.scene.dynamic) + 1), 4, dtype="f4")
        self._objects_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._version = self.scene.geometry_version

    def _write_objects(self, objects_tex: moderngl.Texture) -> None:
        objects = list(self.scene.dynamic.values())
        data = np.zeros((len(objects) + 1, 5, 4), dtype="f4")
        data[0, :3, :4] = np.eye(4)[:3]
        if objects:
            # Batched RigidTransform.matrix(): rotation times scale, translation in the last column.
            rotation = quat_to_matrix(np.stack([o.transform.rotation_xyzw for o in objects]))
            scale = np.stack([o.transform.scale for o in objects])
            data[1:, :3, :3] = rotation * scale[:, None, :]
            data[1:, :3, 3] = np.stack([o.transform.position_world for o in objects])
            data[1:, 3, :3] = np.stack([o.linear_velocity_m_s for o in objects])
            data[1:, 4, :3] = np.stack([o.angular_velocity_rad_s for o in objects])
        objects_tex.write(data.tobytes())

    def _target_for(self, ctx: moderngl.Context, count: int, resolution: int) -> _Atlases:
        """Atlases for count samples at this resolution, kept for reuse (a few shapes at most)."""
        shadow_px = int(min(max(round(self.settings.shadow_map_scale * resolution), 16), self.settings.max_shadow_map_px))
        cols = math.ceil(math.sqrt(count))
        rows = math.ceil(count / cols)
        key = (count, resolution, shadow_px)
        cached = self._targets.get(key)
        if cached is not None:
            return cached
        if len(self._targets) >= 4:  # the schedule alternates between few shapes (2 maps, all maps)
            self._release_targets(next(iter(self._targets)))
        occ_size = (cols * shadow_px, rows * shadow_px)
        out_size = (cols * resolution, rows * resolution)
        limit = int(ctx.info.get("GL_MAX_TEXTURE_SIZE", 8192))
        if max(occ_size + out_size) > limit:
            raise ValueError(f"GLMapBackend: atlas {occ_size} exceeds GL_MAX_TEXTURE_SIZE {limit}")
        occ_tex = ctx.texture(occ_size, 4, dtype="f4")
        occ_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        occ_fbo = ctx.framebuffer(color_attachments=[occ_tex], depth_attachment=ctx.depth_renderbuffer(occ_size))
        out_tex = ctx.texture(out_size, 4, dtype="f4")
        out_fbo = ctx.framebuffer(color_attachments=[out_tex])
        readback = np.empty((out_size[1], out_size[0], 4), dtype="f4")
        self._targets[key] = (cols, rows, shadow_px, occ_tex, occ_fbo, out_tex, out_fbo, readback)
        return self._targets[key]

    def _release_targets(self, key: tuple[int, int, int] | None = None) -> None:
        """Free one atlas set (by key) or all of them."""
        for k in [key] if key is not None else list(self._targets):
            _, _, _, occ_tex, occ_fbo, out_tex, out_fbo, _ = self._targets.pop(k)
            depth = occ_fbo.depth_attachment
            for obj in (occ_fbo, depth, occ_tex, out_fbo, out_tex):
                obj.release()

    # -- frusta --------------------------------------------------------------------------------

    def _frusta(
        self, torus: Torus, window: MapWindow, points: npt.NDArray[np.float64], shadow_px: int
    ) -> tuple[npt.NDArray[np.float64], float]:
        """Per sample: clip-from-(world - eye) matrices (k, 4, 4) and the common far distance, m.

        Each frustum is the tightest off-axis one around the directions from s to the window's
        patch: its border texel centres and a coarse interior grid, so that a fold of the patch in
        the view (near the torus's spindle points) is still inside.
        """
        n = window.resolution
        edge = np.arange(n)
        inner = np.linspace(0, n - 1, 9).round().astype(int)
        ii = np.concatenate([edge, edge, np.zeros(n, int), np.full(n, n - 1), np.repeat(inner, 9)])
        jj = np.concatenate([np.zeros(n, int), np.full(n, n - 1), edge, edge, np.tile(inner, 9)])
        patch = torus_position(torus, window.theta_centers_rad[ii], window.phi_centers_rad[jj])  # (q, 3)
        rel = patch[None, :, :] - points[:, None, :]  # (k, q, 3)
        dist = np.linalg.norm(rel, axis=2)
        unit = rel / np.maximum(dist, 1e-12)[..., None]
        axis = unit.sum(axis=1)
        axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12)
        helper = np.where(np.abs(axis[:, 1:2]) < 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
        right = np.cross(axis, helper)
        right /= np.linalg.norm(right, axis=1, keepdims=True)
        up = np.cross(right, axis)
        forward = np.einsum("kqc,kc->kq", rel, axis)
        max_tan = math.tan(math.radians(self.settings.max_half_angle_deg))
        floor = np.maximum(forward, np.linalg.norm(rel, axis=2) * math.cos(math.radians(self.settings.max_half_angle_deg)))
        tx = np.clip(np.einsum("kqc,kc->kq", rel, right) / floor, -max_tan, max_tan)
        ty = np.clip(np.einsum("kqc,kc->kq", rel, up) / floor, -max_tan, max_tan)
        lo_x, hi_x = tx.min(axis=1), tx.max(axis=1)
        lo_y, hi_y = ty.min(axis=1), ty.max(axis=1)
        # Margin: a fraction of the extent plus two occluder pixels, so border texels stay inside.
        pad_x = (hi_x - lo_x) * (self.settings.frustum_margin + 2.0 / shadow_px) + 1e-6
        pad_y = (hi_y - lo_y) * (self.settings.frustum_margin + 2.0 / shadow_px) + 1e-6
        lo_x, hi_x, lo_y, hi_y = lo_x - pad_x, hi_x + pad_x, lo_y - pad_y, hi_y + pad_y
        far = float(dist.max()) * 1.05 + 1.0
        near = SAMPLE_CLEARANCE_M
        k = len(points)
        view = np.zeros((k, 4, 4))
        view[:, 0, :3], view[:, 1, :3], view[:, 2, :3] = right, up, -axis
        view[:, 3, 3] = 1.0
        proj = np.zeros((k, 4, 4))
        proj[:, 0, 0] = 2.0 / (hi_x - lo_x)
        proj[:, 0, 2] = (hi_x + lo_x) / (hi_x - lo_x)
        proj[:, 1, 1] = 2.0 / (hi_y - lo_y)
        proj[:, 1, 2] = (hi_y + lo_y) / (hi_y - lo_y)
        proj[:, 2, 2] = (far + near) / (near - far)
        proj[:, 2, 3] = 2.0 * far * near / (near - far)
        proj[:, 3, 2] = -1.0
        return proj @ view, far

    # -- the maps ------------------------------------------------------------------------------

    def compute(
        self,
        torus: Torus,
        window: MapWindow,
        sample_points_world: npt.ArrayLike,
        *,
        exclude_ids: Sequence[str | None] | None = None,
        previous_torus: Torus | None = None,
        dt_s: float = 0.0,
    ) -> ShadowVelocityMaps:
        """See base.MapBackend.compute; at most MAX_SAMPLES sample points per call."""
        ctx = self._ctx
        if ctx is None:
            raise ValueError("GLMapBackend was closed")
        points, excluded = check_compute_args(
            window, sample_points_world, exclude_ids, previous_torus, dt_s, max_samples=MAX_SAMPLES
        )
        k, n = len(points), window.resolution
        with ctx:
            self._sync_scene(ctx)
            cols, rows, shadow_px, occ_tex, occ_fbo, out_tex, out_fbo, readback = self._target_for(ctx, k, n)
            view_proj, far = self._frusta(torus, window, points, shadow_px)
            vp_bytes = _mat4_bytes(view_proj, MAX_SAMPLES)

            # Pass 1: occluders from every sample point, one instanced draw.
            occ_fbo.use()
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
            for plane in range(4):
                ctx.enable_direct(_GL_CLIP_DISTANCE0 + plane)
            occ_fbo.clear(_NO_OCCLUDER_DISTANCE, 0.0, 0.0, 0.0, depth=1.0)
            if self._scene_vao is not None:
                objects_tex = self._objects_tex
                assert objects_tex is not None  # _sync_scene made it along with the scene's vertex array
                self._write_objects(objects_tex)
                objects_tex.use(location=1)
                prog = self._occ_prog
                uniform(prog, "u_view_proj").write(vp_bytes)
                uniform(prog, "u_eye").write(_vec3_bytes(points, MAX_SAMPLES))
                exclude = np.full(MAX_SAMPLES, -1, dtype="i4")
                exclude[:k] = [self._object_index.get(oid, -1) if oid is not None else -1 for oid in excluded]
                uniform(prog, "u_exclude").write(exclude.tobytes())
                uniform(prog, "u_tiles").value = (cols, rows)
                uniform(prog, "u_inv_far").value = 1.0 / far
                self._scene_vao.render(moderngl.TRIANGLES, instances=k)
            for plane in range(4):
                ctx.disable_direct(_GL_CLIP_DISTANCE0 + plane)

            # Pass 2: the window's torus patch in texture space, one draw.
            out_fbo.use()
            ctx.disable(moderngl.DEPTH_TEST)
            occ_tex.use(location=0)
            prog = self._toric_prog
            prev = previous_torus if previous_torus is not None else torus
            uniform(prog, "u_res").value = n
            uniform(prog, "u_shadow_px").value = shadow_px
            uniform(prog, "u_count").value = k
            uniform(prog, "u_tiles").value = (cols, rows)
            uniform(prog, "u_window").value = (
                window.theta_min_rad,
                window.phi_min_rad,
                window.theta_step_rad,
                window.phi_step_rad,
            )
            uniform(prog, "u_torus").value = (torus.alpha, torus.arc_radius_m, torus.center_offset_m)
            uniform(prog, "u_basis").write(np.asarray(torus.basis, dtype="f4").tobytes())
            uniform(prog, "u_prev_torus").value = (prev.alpha, prev.arc_radius_m, prev.center_offset_m)
            uniform(prog, "u_prev_basis").write(np.asarray(prev.basis, dtype="f4").tobytes())
            uniform(prog, "u_mid_shift").value = tuple(float(c) for c in torus.mid_world - prev.mid_world)
            uniform(prog, "u_inv_dt").value = 1.0 / dt_s if previous_torus is not None else 0.0
            uniform(prog, "u_keep").value = 1.0 - SEGMENT_END_MARGIN
            uniform(prog, "u_view_proj").write(vp_bytes)
            uniform(prog, "u_mid_from_eye").write(_vec3_bytes(torus.mid_world[None, :] - points, MAX_SAMPLES))
            self._quad_vao.render(moderngl.TRIANGLES)
            out_fbo.read_into(readback, components=4, dtype="f4")

        tiles = readback.reshape(rows, n, cols, n, 4).transpose(0, 2, 1, 3, 4).reshape(rows * cols, n, n, 4)[:k]
        shadow = tiles[..., 0].copy()
        depth = np.where(shadow > 0.5, tiles[..., 3], NOT_OCCLUDED_DEPTH).astype(np.float32)
        return ShadowVelocityMaps(window=window, shadow=shadow, velocity_rad_s=tiles[..., 1:3].copy(), depth_m=depth)

    # -- lifetime ------------------------------------------------------------------------------

    def close(self) -> None:
        """Free every GL object of the backend (the thread's context stays for the next backend);
        the backend is unusable afterwards."""
        if self._ctx is None:
            return
        with self._ctx:
            self._release_targets()
            for obj in [
                self._scene_vao,
                *self._scene_buffers,
                self._objects_tex,
                self._quad_vao,
                self._quad_vbo,
                self._occ_prog,
                self._toric_prog,
            ]:
                if obj is not None:
                    obj.release()
        self._ctx = None

    def __enter__(self) -> GLMapBackend:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
