"""Offscreen colour rendering of rigid triangle meshes through EGL (moderngl), for videos.

`moderngl.create_standalone_context(backend='egl')` needs no X display: it runs on Mesa's llvmpipe
on machines without a GPU and on the GPU's driver where there is one.

Camera convention as in `camdirector.geometry.camera`: the camera looks down its local -Z with +Y
up, the pose's rotation is camera-to-world, and the lens gives the vertical field of view and the
aspect. Images come back (h, w, 3) uint8 with the top row first.

Per-frame cost is one instanced draw call per distinct geometry: vertex data is uploaded once by
`add_mesh`, meshes with identical vertices and faces share it, and each mesh is one instance whose
model matrix, normal matrix, colour and checker size travel as per-instance attributes
(`set_transform` only stores them; `render` uploads them in one buffer write per geometry). On
llvmpipe each draw call costs about as much as its pixels, so a character of 40 capsule pieces
drawn as two instanced calls instead of 40 single ones renders 2-3x faster.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import moderngl
import numpy as np
import numpy.typing as npt

from camdirector.geometry.camera import CameraPose, Lens
from camdirector.geometry.gl_context import egl_context, uniform
from camdirector.geometry.transforms import quat_to_matrix

# Pale blue-grey: grey columns and the orange avatar stand out against it. Fog fades distance to
# this same colour, which softens the far edge of the ground slab against the sky.
SKY_RGB = (0.72, 0.80, 0.88)
# Direction *towards* the light, world frame: high and from one side so that two faces of a box
# seen from a typical camera get different shades and shapes read as solids, not silhouettes.
LIGHT_DIR_WORLD = (0.45, 0.80, 0.30)

_VERTEX_SHADER = """
#version 330
uniform mat4 u_view_proj;
in vec3 in_position;
in vec3 in_normal;
// Per instance (one per mesh sharing this geometry).
in mat4 in_model;
in mat3 in_normal_matrix;
in vec3 in_color;
in float in_checker_m;
out vec3 v_normal_world;
out vec3 v_position_world;
flat out vec3 v_color;
flat out float v_checker_m;
void main() {
    vec4 p_world = in_model * vec4(in_position, 1.0);
    v_position_world = p_world.xyz;
    v_normal_world = in_normal_matrix * in_normal;
    v_color = in_color;
    v_checker_m = in_checker_m;
    gl_Position = u_view_proj * p_world;
}
"""

# Lambert from a key light plus a weak fill, with a hemisphere ambient term (sky above, ground
# bounce below) so faces turned away from the light keep some shape; an optional world-space
# checker so ground motion is visible in video;
# distance fog so the horizon blends into the sky.
_FRAGMENT_SHADER = """
#version 330
uniform vec3 u_light_dir_world;
uniform vec3 u_sky_rgb;
uniform vec3 u_camera_world;
uniform float u_fog_start_m;
uniform float u_fog_end_m;
in vec3 v_normal_world;
in vec3 v_position_world;
flat in vec3 v_color;
flat in float v_checker_m;
out vec4 f_color;
void main() {
    vec3 n = normalize(v_normal_world);
    float key = max(dot(n, u_light_dir_world), 0.0);
    // A weak fill from the opposite side, as if bounced, keeps faces away from the key light
    // from going near-black (columns seen against the light read as flat dark bars otherwise).
    vec3 fill_dir = normalize(vec3(-u_light_dir_world.x, 0.4, -u_light_dir_world.z));
    float fill = max(dot(n, fill_dir), 0.0);
    float hemi = 0.5 + 0.5 * n.y;
    vec3 color = v_color;
    if (v_checker_m > 0.0) {
        vec2 cell = floor(v_position_world.xz / v_checker_m);
        color *= (mod(cell.x + cell.y, 2.0) < 1.0) ? 1.0 : 0.86;
    }
    vec3 lit = color * (0.5 * key + 0.2 * fill + mix(0.30, 0.45, hemi));
    float dist = length(v_position_world - u_camera_world);
    float fog = clamp((dist - u_fog_start_m) / (u_fog_end_m - u_fog_start_m), 0.0, 1.0);
    f_color = vec4(mix(lit, u_sky_rgb, fog), 1.0);
}
"""


def perspective_matrix(lens: Lens, near_m: float, far_m: float) -> npt.NDArray[np.float64]:
    """(4, 4) float64 OpenGL clip-from-camera matrix for the lens (vertical fov, aspect)."""
    if not 0.0 < near_m < far_m:
        raise ValueError(f"need 0 < near_m < far_m, got near_m={near_m}, far_m={far_m}")
    f = 1.0 / lens.tan_half_fov_y
    m = np.zeros((4, 4))
    m[0, 0] = f / lens.aspect
    m[1, 1] = f
    m[2, 2] = (far_m + near_m) / (near_m - far_m)
    m[2, 3] = 2.0 * far_m * near_m / (near_m - far_m)
    m[3, 2] = -1.0
    return m


def top_down_matrix(
    x_range_m: tuple[float, float], z_range_m: tuple[float, float], y_range_m: tuple[float, float]
) -> npt.NDArray[np.float64]:
    """(4, 4) float64 clip-from-world matrix of an orthographic view straight down: world x across
    the image left to right over x_range_m, world z down it top to bottom over z_range_m (as the
    dashboard's top view draws them), depth from the top of y_range_m (near) to its bottom (far)."""
    (x0, x1), (z0, z1), (y0, y1) = x_range_m, z_range_m, y_range_m
    if not (x1 > x0 and z1 > z0 and y1 > y0):
        raise ValueError("top_down_matrix: each range must be (low, high) with high > low")
    m = np.zeros((4, 4))
    m[0, 0], m[0, 3] = 2.0 / (x1 - x0), -(x1 + x0) / (x1 - x0)
    m[1, 2], m[1, 3] = -2.0 / (z1 - z0), (z1 + z0) / (z1 - z0)  # z0 at the top row (clip y = 1)
    m[2, 1], m[2, 3] = -2.0 / (y1 - y0), (y1 + y0) / (y1 - y0)  # the highest point nearest
    m[3, 3] = 1.0
    return m


def view_matrix(pose: CameraPose) -> npt.NDArray[np.float64]:
    """(4, 4) float64 camera-from-world matrix: the inverse of the pose's camera-to-world."""
    r = quat_to_matrix(pose.rotation_xyzw)
    m = np.eye(4)
    m[:3, :3] = r.T
    m[:3, 3] = -r.T @ np.asarray(pose.position_world, dtype=np.float64)
    return m


def _gl_matrix(m: npt.NDArray[np.float64]) -> bytes:
    # GLSL reads matrices column-major; numpy is row-major, so send the transpose.
    return np.ascontiguousarray(m.T, dtype="f4").tobytes()


# One instance row, float32: model matrix (16, column-major), normal matrix (9, column-major),
# colour (3), checker side (1); the slices below index it.
_INSTANCE_FORMAT = "16f 9f 3f 1f/i"
_INSTANCE_ATTRIBUTES = ("in_model", "in_normal_matrix", "in_color", "in_checker_m")
_MODEL, _NORMAL, _COLOR, _CHECKER = slice(0, 16), slice(16, 25), slice(25, 28), slice(28, 29)
_INSTANCE_FLOATS = 29


@dataclass
class _Geometry:
    """Vertex data shared by every mesh added with the same vertices and faces; `rows` are those
    meshes' rows in the renderer's instance table, drawn as one instanced call."""

    vbo: moderngl.Buffer
    instance_buffer: moderngl.Buffer
    vao: moderngl.VertexArray
    closed: bool
    rows: list[int]


class OffscreenRenderer:
    """Flat-shaded colour renderer of rigid meshes into an offscreen framebuffer.

    width_px, height_px: image size in pixels, each in [1, 8192]. msaa_samples: multisampling,
    0 = off (clamped to what the driver offers). 4 smooths edges and far checker moire but, on
    llvmpipe (2 busy cores, the ~2k-triangle demo scene, median per frame) it about doubles the
    cost at 640x360 (4-9 ms -> 8-16 ms) and triples it at 1280x720 (11-17 ms -> 33-75 ms); on a
    GPU it is close to free. fog_start_m / fog_end_m: distance band in metres over which geometry
    fades into the sky colour. context: a moderngl context to draw in, shared with other
    renderers of the same thread (each keeps its own framebuffer, buffers and program, and makes
    the context current around its own calls); None creates one for this renderer alone.

    Use as a context manager or call `release()`: it owns its GL objects, and its context when it
    created it.
    """

    def __init__(
        self,
        width_px: int,
        height_px: int,
        *,
        msaa_samples: int = 0,
        sky_rgb: tuple[float, float, float] = SKY_RGB,
        light_dir_world: tuple[float, float, float] = LIGHT_DIR_WORLD,
        fog_start_m: float = 20.0,
        fog_end_m: float = 90.0,
        context: moderngl.Context | None = None,
    ) -> None:
        width_px, height_px = int(width_px), int(height_px)
        if not (1 <= width_px <= 8192 and 1 <= height_px <= 8192):
            raise ValueError(f"image size must be in [1, 8192] px, got {width_px}x{height_px}")
        if not 0.0 <= fog_start_m < fog_end_m:
            raise ValueError("need 0 <= fog_start_m < fog_end_m")
        self.width_px = width_px
        self.height_px = height_px
        red, green, blue = sky_rgb
        self.sky_rgb = (float(red), float(green), float(blue))
        self._owns_context = context is None
        if context is None:
            try:
                context = egl_context()
            except Exception as err:  # EGL missing or no usable driver: say which call failed
                raise RuntimeError(f"OffscreenRenderer: no EGL GL context ({err})") from err
        self._ctx: moderngl.Context | None = context
        ctx = context
        with ctx:
            self._setup(ctx, width_px, height_px, msaa_samples, light_dir_world, fog_start_m, fog_end_m)

    def _setup(
        self,
        ctx: moderngl.Context,
        width_px: int,
        height_px: int,
        msaa_samples: int,
        light_dir_world: tuple[float, float, float],
        fog_start_m: float,
        fog_end_m: float,
    ) -> None:
        """The program, framebuffers and tables (the context `ctx` is current)."""
        self._prog = ctx.program(vertex_shader=_VERTEX_SHADER, fragment_shader=_FRAGMENT_SHADER)
        light = np.asarray(light_dir_world, dtype=np.float64)
        uniform(self._prog, "u_light_dir_world").value = tuple(light / np.linalg.norm(light))
        uniform(self._prog, "u_sky_rgb").value = self.sky_rgb
        uniform(self._prog, "u_fog_start_m").value = float(fog_start_m)
        uniform(self._prog, "u_fog_end_m").value = float(fog_end_m)
        self._u_view_proj = uniform(self._prog, "u_view_proj")
        self._u_camera = uniform(self._prog, "u_camera_world")

        size = (width_px, height_px)
        samples = min(int(msaa_samples), ctx.max_samples) if msaa_samples > 1 else 0
        # A multisampled framebuffer cannot be read directly: draw into it, then resolve into a
        # plain one. Without multisampling the two are the same framebuffer.
        self._draw_fbo = ctx.framebuffer(
            color_attachments=[ctx.renderbuffer(size, 4, samples=samples)],
            depth_attachment=ctx.depth_renderbuffer(size, samples=samples),
        )
        self._resolve_fbo = self._draw_fbo
        if samples:
            self._resolve_fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer(size, 4)])
        self._readback = bytearray(width_px * height_px * 3)
        # Mesh id -> its row in the instance table; the dict keeps insertion order.
        self._rows: dict[str, int] = {}
        self._instances = np.zeros((0, _INSTANCE_FLOATS), dtype="f4")  # (meshes, 29) float32
        # (flat-shaded vertex bytes, closed) -> geometry: identical meshes share one draw call.
        self._geometries: dict[tuple[bytes, bool], _Geometry] = {}
        self._closed = np.zeros(0, dtype=bool)  # (meshes,) per row of the instance table

    # -- scene -------------------------------------------------------------------------------

    def add_mesh(
        self,
        mesh_id: str,
        vertices: npt.ArrayLike,
        faces: npt.ArrayLike,
        color_rgb: tuple[float, float, float],
        *,
        checker_m: float = 0.0,
        closed: bool = False,
    ) -> None:
        """Upload a mesh once; it starts at the identity transform.

        vertices: (n, 3) float local coordinates, metres. faces: (m, 3) int indices into vertices,
        counter-clockwise seen from outside (the normal's sign depends on it, and culling when
        closed). color_rgb: 3 floats in [0, 1]. checker_m: side of a world-space checker pattern
        drawn on this mesh (0 = plain), e.g. 1-2 m on the ground so camera motion reads in video.
        closed: the mesh is watertight with consistent winding, so its back faces are always
        hidden by its front faces and are culled (about a quarter of the cost of a frame of small
        spheres and cylinders on llvmpipe); it must then not be mirrored, and a camera inside it
        sees nothing of it. Open meshes (a lone quad, a terrain sheet) show both sides.
        """
        if mesh_id in self._rows:
            raise ValueError(f"mesh id {mesh_id!r} already added")
        v = np.asarray(vertices, dtype=np.float64)
        f = np.asarray(faces)
        if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
            raise ValueError("vertices must be (n, 3) with n > 0")
        if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0 or not np.issubdtype(f.dtype, np.integer):
            raise ValueError("faces must be (m, 3) integer with m > 0")
        if f.min() < 0 or f.max() >= len(v):
            raise ValueError("faces index outside vertices")
        if not np.all(np.isfinite(v)):
            raise ValueError("vertices must be finite")
        color = np.asarray(color_rgb, dtype=np.float64)
        if color.shape != (3,) or np.any(color < 0.0) or np.any(color > 1.0):
            raise ValueError("color_rgb must be 3 floats in [0, 1]")

        # Flat shading: each triangle gets its own three vertices carrying the face normal, so the
        # shader needs no derivatives and shared box corners do not smear light across edges.
        tri = v[f]  # (m, 3, 3) corners
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # (m, 3)
        length = np.linalg.norm(normal, axis=1, keepdims=True)
        normal = np.divide(normal, length, out=np.zeros_like(normal), where=length > 0.0)
        interleaved = np.empty((len(f), 3, 6), dtype="f4")  # (m, 3 corners, position + normal)
        interleaved[:, :, :3] = tri
        interleaved[:, :, 3:] = normal[:, None, :]
        key = (interleaved.tobytes(), bool(closed))
        with self._live_context():
            self._add_instance(mesh_id, key, color, checker_m)

    def _add_instance(self, mesh_id: str, key: tuple[bytes, bool], color: npt.NDArray[np.float64], checker_m: float) -> None:
        """One row of the instance table for geometry `key`, whose buffers are made on first use."""
        geometry = self._geometries.get(key)
        closed = key[1]
        if geometry is None:
            ctx = self._live_context()
            vbo = ctx.buffer(key[0])
            instance_buffer = ctx.buffer(reserve=_INSTANCE_FLOATS * 4)
            vao = ctx.vertex_array(
                self._prog,
                [
                    (vbo, "3f 3f", "in_position", "in_normal"),
                    (instance_buffer, _INSTANCE_FORMAT, *_INSTANCE_ATTRIBUTES),
                ],
            )
            geometry = self._geometries[key] = _Geometry(vbo, instance_buffer, vao, closed, [])
        row = np.zeros(_INSTANCE_FLOATS, dtype="f4")
        row[_MODEL] = np.eye(4).ravel()
        row[_NORMAL] = np.eye(3).ravel()
        row[_COLOR] = color
        row[_CHECKER] = checker_m
        self._rows[mesh_id] = len(self._instances)
        self._instances = np.vstack([self._instances, row[None]])
        self._closed = np.append(self._closed, closed)
        geometry.rows.append(self._rows[mesh_id])
        geometry.instance_buffer.orphan(len(geometry.rows) * _INSTANCE_FLOATS * 4)

    def set_transform(self, mesh_id: str, matrix_local_to_world: npt.ArrayLike) -> None:
        """Place a mesh: matrix_local_to_world (4, 4) float, e.g. `RigidTransform.matrix()`."""
        self.set_transforms([mesh_id], np.asarray(matrix_local_to_world, dtype=np.float64)[None])

    def set_transforms(self, mesh_ids: list[str], matrices_local_to_world: npt.ArrayLike) -> None:
        """Place several meshes at once: matrices_local_to_world (k, 4, 4) float, one per id.
        Checked and inverted in one numpy pass: an animated character sets dozens per frame."""
        try:
            rows = [self._rows[mesh_id] for mesh_id in mesh_ids]
        except KeyError as err:
            raise KeyError(f"unknown mesh id {err.args[0]!r}") from None
        m = np.asarray(matrices_local_to_world, dtype=np.float64)
        if m.shape != (len(rows), 4, 4) or not np.all(np.isfinite(m)):
            raise ValueError("matrix_local_to_world must be a finite (4, 4) matrix per mesh")
        # Inverse from cross products of the columns (rows of the inverse times det): no LAPACK
        # call per frame, and the determinant comes with it.
        col = m[:, :3, :3].transpose(0, 2, 1)  # (k, 3 columns, 3)
        # Row i is column i+1 x column i+2, written out: np.cross costs ~0.1 ms a call.
        u, v = col[:, [1, 2, 0]], col[:, [2, 0, 1]]
        cofactor_rows = u[..., [1, 2, 0]] * v[..., [2, 0, 1]] - u[..., [2, 0, 1]] * v[..., [1, 2, 0]]
        det = np.einsum("ij,ij->i", col[:, 0], cofactor_rows[:, 0])
        if np.any(np.abs(det) < 1e-12):
            raise ValueError("matrix_local_to_world is singular (zero scale?)")
        if np.any((det < 0.0) & self._closed[rows]):
            raise ValueError("a closed mesh cannot be mirrored: its front faces would be culled")
        # GLSL reads matrices column-major; numpy is row-major, so store the transposes.
        self._instances[rows, _MODEL] = m.transpose(0, 2, 1).reshape(len(rows), 16)
        # Inverse transpose keeps normals perpendicular under non-uniform scale (stored
        # transposed: the inverse).
        self._instances[rows, _NORMAL] = (cofactor_rows / det[:, None, None]).reshape(len(rows), 9)

    def mesh_ids(self) -> list[str]:
        """Ids of the meshes added so far, in insertion order."""
        return list(self._rows)

    # -- frames ------------------------------------------------------------------------------

    def render(self, pose: CameraPose, lens: Lens, near_m: float = 0.05, far_m: float = 500.0) -> npt.NDArray[np.uint8]:
        """(h, w, 3) uint8 image, top row first, seen from pose through lens.

        The projection uses lens.vertical_fov_deg and lens.aspect (as `project_to_screen` does);
        pass a lens whose aspect equals width_px / height_px or the image is stretched.
        """
        return self.render_view(perspective_matrix(lens, near_m, far_m) @ view_matrix(pose), pose.position_world)

    def render_view(self, view_proj: npt.ArrayLike, eye_world: Iterable[float]) -> npt.NDArray[np.uint8]:
        """(h, w, 3) uint8 image, top row first, through any clip-from-world matrix (4, 4) (e.g.
        `top_down_matrix`); eye_world (3,) m is where the fog measures distance from."""
        ctx = self._live_context()
        with ctx:
            return self._draw(ctx, np.asarray(view_proj, dtype=np.float64), eye_world)

    def _live_context(self) -> moderngl.Context:
        """The renderer's context; ValueError once the renderer is released."""
        if self._ctx is None:
            raise ValueError("OffscreenRenderer was released")
        return self._ctx

    def _draw(
        self, ctx: moderngl.Context, view_proj: npt.NDArray[np.float64], eye_world: Iterable[float]
    ) -> npt.NDArray[np.uint8]:
        self._draw_fbo.use()
        ctx.enable(moderngl.DEPTH_TEST)
        self._draw_fbo.clear(*self.sky_rgb, 1.0, depth=1.0)
        self._u_view_proj.write(_gl_matrix(view_proj))
        self._u_camera.value = tuple(float(c) for c in eye_world)
        for geometry in self._geometries.values():
            if geometry.closed:
                ctx.enable(moderngl.CULL_FACE)
            else:
                ctx.disable(moderngl.CULL_FACE)
            geometry.instance_buffer.write(self._instances[geometry.rows].tobytes())
            geometry.vao.render(moderngl.TRIANGLES, instances=len(geometry.rows))
        if self._draw_fbo is not self._resolve_fbo:
            ctx.copy_framebuffer(self._resolve_fbo, self._draw_fbo)
        self._resolve_fbo.read_into(self._readback, components=3, alignment=1)
        image = np.frombuffer(self._readback, dtype=np.uint8)
        image = image.reshape(self.height_px, self.width_px, 3)
        # GL's first row is the bottom one; the copy also frees the caller from our reused buffer.
        return image[::-1].copy()

    # -- lifetime ----------------------------------------------------------------------------

    def release(self) -> None:
        """Free the GL objects, and the context when the renderer made it; the renderer is unusable
        afterwards."""
        if self._ctx is None:
            return
        with self._ctx:
            for geometry in self._geometries.values():
                geometry.vao.release()
                geometry.vbo.release()
                geometry.instance_buffer.release()
            framebuffers = {self._draw_fbo, self._resolve_fbo}
            for fbo in framebuffers:
                for attachment in [*fbo.color_attachments, fbo.depth_attachment]:
                    if attachment is not None:
                        attachment.release()
                fbo.release()
            self._prog.release()
        self._geometries.clear()
        if self._owns_context:
            self._ctx.release()
        self._ctx = None

    def __enter__(self) -> OffscreenRenderer:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.release()
