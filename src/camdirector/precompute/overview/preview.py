"""Preview of an overview camera: the clip rendered through the path offscreen (EGL), as an mp4
and a contact sheet (the paper's last stage, "render the overview", Figure 3).

The character is drawn as one capsule per rigid bone (a cylinder scaled along the bone plus a
sphere at each end, radius from the body part as in limb_visibility.py), coloured by body part,
on a checkered ground plane at the clip's floor height. Shot boundaries are marked by a coloured
border for `border_flash_s` at the start of every shot after the first, in that shot's colour,
and every frame carries a "shot k/S" label. The contact sheet is a grid with two tiles per shot
(its first frame and its middle frame), each labelled with shot, frame and time.

Cost (llvmpipe, 2 cores, 480x270): about 3-5 ms a frame to render (the character's capsules
share two instanced draw calls) and ~3 ms of CPU to encode; with one process that keeps ~1.4
cores busy, so the video is rendered by `processes` processes at once, each a part of the frame
range, and joined without re-encoding. Clips faster than `max_fps` are shown every k-th frame
(CMU's 120 fps at 30 fps).
"""

from __future__ import annotations

import functools
import math
import os
import pickle
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from camdirector.geometry import meshes
from camdirector.geometry.camera import CameraPose, Lens
from camdirector.geometry.render import OffscreenRenderer
from camdirector.geometry.video import VideoWriter, concat_videos
from camdirector.infra.process_lifetime import die_with_parent
from camdirector.precompute.overview.body_parts import BodyPart, BodyPartMap, rigid_bones
from camdirector.precompute.overview.bvh import MotionClip

PART_RGB = {
    BodyPart.HEAD: (0.96, 0.80, 0.35),
    BodyPart.TORSO: (0.92, 0.52, 0.22),
    BodyPart.LEFT_ARM: (0.20, 0.55, 0.90),
    BodyPart.RIGHT_ARM: (0.86, 0.24, 0.30),
    BodyPart.LEFT_LEG: (0.22, 0.70, 0.42),
    BodyPart.RIGHT_LEG: (0.60, 0.32, 0.80),
}
# Capsule radius per part, character heights (thinner than limb_visibility's ellipsoids, which
# stand for the flesh around a whole part: capsules per bone overlap at the joints).
PART_RADIUS_HEIGHTS = {
    BodyPart.HEAD: 0.055,
    BodyPart.TORSO: 0.06,
    BodyPart.LEFT_ARM: 0.025,
    BodyPart.RIGHT_ARM: 0.025,
    BodyPart.LEFT_LEG: 0.035,
    BodyPart.RIGHT_LEG: 0.035,
}
SHOT_RGB = (
    (230, 57, 70),
    (42, 157, 143),
    (244, 162, 97),
    (69, 123, 157),
    (131, 56, 236),
    (255, 190, 11),
    (58, 134, 255),
    (251, 86, 7),
)


@dataclass(frozen=True)
class PreviewSettings:
    """height_px: video height, pixels (width from the aspect, both even). [16, 2160]
    max_fps: highest video rate; faster clips show every k-th frame, Hz. (0, 240]
    crf, preset: x264 quality and speed (geometry/video.py).
    border_flash_s: how long the shot-start border shows, s. [0, 10]; border_px: its width.
    tile_height_px: contact-sheet tile height, pixels. [16, 1080]
    processes: processes rendering and encoding the video at once, each a consecutive part of the
      frames, joined without re-encoding; 2 uses both cores of a 2-core machine (one process
      keeps them ~70% busy: the Python loop and GL draws are serial). [1, 16]
    min_frames_per_process: fewer frames than this per process and fewer processes are used: a
      child takes ~1 s to start (imports, GL context), ~150-200 frames' worth. [1, 100000]
    head_start_frames: frames this process renders beyond an equal share, while the children
      start (each child keeps at least min_frames_per_process). [0, 100000]"""

    height_px: int = 270
    max_fps: float = 30.0
    crf: int = 23
    preset: str = "veryfast"
    border_flash_s: float = 0.4
    border_px: int = 6
    tile_height_px: int = 180
    processes: int = 2
    min_frames_per_process: int = 300
    head_start_frames: int = 200

    def __post_init__(self):
        if not 16 <= self.height_px <= 2160:
            raise ValueError("height_px must be in [16, 2160]")
        if not 0.0 < self.max_fps <= 240.0:
            raise ValueError("max_fps must be in (0, 240]")
        if not 0.0 <= self.border_flash_s <= 10.0:
            raise ValueError("border_flash_s must be in [0, 10]")
        if not 16 <= self.tile_height_px <= 1080:
            raise ValueError("tile_height_px must be in [16, 1080]")
        if not 1 <= self.processes <= 16:
            raise ValueError("processes must be in [1, 16]")
        if not 1 <= self.min_frames_per_process <= 100_000:
            raise ValueError("min_frames_per_process must be in [1, 100000]")
        if not 0 <= self.head_start_frames <= 100_000:
            raise ValueError("head_start_frames must be in [0, 100000]")


@dataclass(frozen=True)
class PreviewCamera:
    """The camera per clip frame (F): position_m (F, 3), rotation_xyzw (F, 4) camera-to-world,
    vertical_fov_deg (F,); shots (S, 2) [first, last] clip frames; aspect width / height."""

    position_m: np.ndarray
    rotation_xyzw: np.ndarray
    vertical_fov_deg: np.ndarray
    shots: np.ndarray
    aspect: float

    @classmethod
    def from_result(cls, result) -> PreviewCamera:
        """From a pipeline.OverviewResult."""
        return cls(
            position_m=result.camera_position_m,
            rotation_xyzw=result.rotation_xyzw,
            vertical_fov_deg=result.vertical_fov_deg,
            shots=result.shots,
            aspect=result.settings.aspect,
        )

    def shot_of(self, frame: int) -> int:
        return int(np.searchsorted(self.shots[:, 0], frame, side="right") - 1)


def even_size(aspect: float, height_px: int) -> tuple[int, int]:
    """(width, height) in pixels, both even, width / height as close to `aspect` as that allows."""
    h = max(2, int(height_px) // 2 * 2)
    w = max(2, int(round(h * aspect / 2.0)) * 2)
    return w, h


def _bone_matrices(a: np.ndarray, b: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """(B, 4, 4) unit cylinder (radius 1, height 1 along +Y, centred) -> capsule body from a (B, 3)
    to b (B, 3) with radius (B,); bones of zero length get a zero axis (the caller skips them)."""
    axis = b - a
    length = np.linalg.norm(axis, axis=1)
    y = axis / np.maximum(length, 1e-12)[:, None]
    helper = np.where((np.abs(y[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    x = np.cross(y, helper)
    x /= np.maximum(np.linalg.norm(x, axis=1), 1e-12)[:, None]
    z = np.cross(x, y)
    m = np.zeros((len(a), 4, 4))
    m[:, :3, 0], m[:, :3, 1], m[:, :3, 2] = x * radius[:, None], axis, z * radius[:, None]
    m[:, :3, 3] = 0.5 * (a + b)
    m[:, 3, 3] = 1.0
    return m


class CharacterScene:
    """An OffscreenRenderer holding a clip's character (capsules per bone) and a ground plane.

    Use as a context manager or call `release()` (it owns a GL context)."""

    def __init__(self, clip: MotionClip, parts: BodyPartMap, width_px: int, height_px: int) -> None:
        self.clip, self.parts = clip, parts
        # (F, J + E, 3): the clip concatenates joints and end sites anew on every access.
        self.points_m = points = clip.all_points_m
        parent, child = rigid_bones(clip)
        lengths = np.linalg.norm(points[:, child] - points[:, parent], axis=2).mean(axis=0)
        keep = lengths > 1e-4
        self.parent, self.child = parent[keep], child[keep]
        n_joints = len(clip.joint_names)
        owner = np.where(self.child < n_joints, self.child, clip.end_site_parents[np.maximum(self.child - n_joints, 0)])
        self.part = parts.part_of_joint[owner]
        height = clip.character_height_m()
        self.radius = np.array([PART_RADIUS_HEIGHTS[BodyPart(p)] * height for p in self.part])
        ends = np.unique(np.concatenate([self.parent, self.child]))
        self.sphere_points = ends
        self.sphere_radius = np.zeros(len(ends))
        self.sphere_part = np.zeros(len(ends), dtype=np.int64)
        for k, pt in enumerate(ends):
            touching = np.flatnonzero((self.parent == pt) | (self.child == pt))
            best = touching[np.argmax(self.radius[touching])]
            self.sphere_radius[k] = self.radius[best]
            self.sphere_part[k] = self.part[best]
        body = points[:, parts.body_points]
        self.floor_y_m = float(np.percentile(body[:, :, 1].min(axis=1), 2.0))
        self.renderer = OffscreenRenderer(width_px, height_px, fog_start_m=30.0, fog_end_m=120.0)
        cyl = meshes.cylinder(1.0, 1.0, sections=12)
        sph = meshes.sphere(1.0)
        self.bone_ids = np.array([f"bone{i}" for i in range(len(self.part))], dtype=object)
        self.joint_ids = [f"joint{k}" for k in range(len(self.sphere_part))]
        for mesh_id, p in zip(self.bone_ids, self.part):
            self.renderer.add_mesh(mesh_id, cyl.vertices, cyl.faces, PART_RGB[BodyPart(p)], closed=True)
        for mesh_id, p in zip(self.joint_ids, self.sphere_part):
            self.renderer.add_mesh(mesh_id, sph.vertices, sph.faces, PART_RGB[BodyPart(int(p))], closed=True)
        centre = body.reshape(-1, 3).mean(axis=0)
        extent = float(np.ptp(body[:, :, [0, 2]].reshape(-1, 2), axis=0).max()) + 40.0
        ground = meshes.box((extent, 0.02, extent))
        self.renderer.add_mesh("ground", ground.vertices, ground.faces, (0.78, 0.78, 0.74), checker_m=0.5, closed=True)
        g = np.eye(4)
        g[:3, 3] = (centre[0], self.floor_y_m - 0.01, centre[2])
        self.renderer.set_transform("ground", g)

    def pose_character(self, frame: int) -> None:
        pts = self.points_m[frame]
        a, b = pts[self.parent], pts[self.child]
        matrices = _bone_matrices(a, b, self.radius)
        placed = np.flatnonzero(np.linalg.norm(b - a, axis=1) > 1e-6)  # a zero-length bone keeps its last place
        joints = self.sphere_radius[:, None, None] * np.eye(4)
        joints[:, 3, 3] = 1.0
        joints[:, :3, 3] = pts[self.sphere_points]
        self.renderer.set_transforms(self.bone_ids[placed].tolist() + self.joint_ids, np.concatenate([matrices[placed], joints]))

    def render(self, frame: int, camera: PreviewCamera) -> np.ndarray:
        """(h, w, 3) uint8 image of clip frame `frame` through `camera`."""
        self.pose_character(frame)
        fov = float(camera.vertical_fov_deg[frame])
        pose = CameraPose(camera.position_m[frame], camera.rotation_xyzw[frame], fov)
        lens = Lens(fov, self.renderer.width_px / self.renderer.height_px)
        return self.renderer.render(pose, lens, near_m=0.02, far_m=300.0)

    def release(self) -> None:
        self.renderer.release()

    def __enter__(self) -> CharacterScene:
        return self

    def __exit__(self, *exc) -> None:
        self.release()


@functools.lru_cache(maxsize=8)
def _font(size: int):
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1
        return ImageFont.load_default()


def shot_rgb(shot: int) -> tuple[int, int, int]:
    return SHOT_RGB[shot % len(SHOT_RGB)]


def mark_frame(image: np.ndarray, shot: int, shot_count: int, time_s: float, flash: bool, border_px: int) -> np.ndarray:
    """Draw the shot label (always) and the shot-start border (when `flash`) onto a copy."""
    out = image.copy()
    if flash and border_px > 0:
        c = np.array(shot_rgb(shot), dtype=np.uint8)
        out[:border_px], out[-border_px:] = c, c
        out[:, :border_px], out[:, -border_px:] = c, c
    font = _font(max(10, out.shape[0] // 20))
    text = f"shot {shot + 1}/{shot_count}  {time_s:5.2f} s"
    x, y = border_px + 4, border_px + 2
    # Only the label's box goes through PIL (a whole frame costs ~1 ms a frame in conversions);
    # the text is drawn over the same pixels either way, so the result is the same.
    left, top, right, bottom = (int(v) for v in font.getbbox(text))
    x0, y0 = max(0, x + left - 1), max(0, y + top - 1)
    x1, y1 = min(out.shape[1], x + right + 1), min(out.shape[0], y + bottom + 1)
    if x1 > x0 and y1 > y0:
        box = Image.fromarray(out[y0:y1, x0:x1])
        ImageDraw.Draw(box).text((x - x0, y - y0), text, fill=(20, 20, 20), font=font)
        out[y0:y1, x0:x1] = np.asarray(box)
    return out


def preview_frames(frame_count: int, frame_time_s: float, max_fps: float) -> tuple[np.ndarray, float]:
    """(clip frames shown, video fps): every k-th frame with k = ceil(clip rate / max_fps)."""
    step = max(1, math.ceil((1.0 / frame_time_s) / max_fps - 1e-3))  # 30.00003 fps is 30
    return np.arange(0, frame_count, step), 1.0 / (frame_time_s * step)


def _write_frames(
    scene: CharacterScene, camera: PreviewCamera, frames: np.ndarray, video: VideoWriter, settings: PreviewSettings
) -> None:
    """Render, mark and append the clip frames `frames` (k,) int to `video`."""
    dt = scene.clip.frame_time_s
    flash_frames = settings.border_flash_s / dt
    for f in frames:
        shot = camera.shot_of(int(f))
        since_cut = f - camera.shots[shot, 0]
        image = scene.render(int(f), camera)
        video.write(mark_frame(image, shot, len(camera.shots), f * dt, shot > 0 and since_cut < flash_frames, settings.border_px))


def render_video(
    scene: CharacterScene, camera: PreviewCamera, path: str | Path, settings: PreviewSettings = PreviewSettings()
) -> int:
    """Write the preview mp4; returns the number of video frames.

    With `settings.processes` > 1 and enough frames, the frame range is cut into consecutive
    parts: this process renders and encodes the first, one child process per other part does the
    same with its own GL context and encoder, and the parts are joined without re-encoding."""
    clip = scene.clip
    frames, fps = preview_frames(clip.frame_count, clip.frame_time_s, settings.max_fps)
    size = (scene.renderer.width_px, scene.renderer.height_px)
    processes = min(settings.processes, len(frames) // settings.min_frames_per_process)
    if processes <= 1:
        with VideoWriter(path, fps, size, crf=settings.crf, preset=settings.preset) as video:
            _write_frames(scene, camera, frames, video, settings)
            return video.frames_written
    # This process starts rendering at once, children ~1 s later: it takes that head start on
    # top of an equal share.
    head = min(
        (len(frames) + (processes - 1) * settings.head_start_frames) // processes,
        len(frames) - (processes - 1) * settings.min_frames_per_process,
    )
    chunks = [frames[:head], *np.array_split(frames[head:], processes - 1)]
    path = Path(path)
    with tempfile.TemporaryDirectory(prefix=".preview-", dir=path.parent) as tmp_dir:
        tmp = Path(tmp_dir)
        segments = [tmp / f"part{k}.mp4" for k in range(processes)]
        children = []
        try:
            for k in range(1, processes):
                job = tmp / f"part{k}.pickle"
                job.write_bytes(
                    pickle.dumps((os.getpid(), clip, scene.parts, camera, settings, size, fps, chunks[k], segments[k]))
                )
                # stderr to a file, not a pipe: a chatty child can never block on a full pipe.
                with open(tmp / f"part{k}.log", "wb") as log:
                    children.append(
                        subprocess.Popen(
                            [sys.executable, "-m", __name__, str(job)],
                            stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL,
                            stderr=log,
                        )
                    )
            with VideoWriter(segments[0], fps, size, crf=settings.crf, preset=settings.preset) as video:
                _write_frames(scene, camera, chunks[0], video, settings)
            for k, child in enumerate(children, start=1):
                if child.wait() != 0:
                    tail = (tmp / f"part{k}.log").read_text(errors="replace").strip()[-2000:]
                    raise RuntimeError(f"preview part {k} failed (exit {child.returncode}): {tail}")
        finally:
            for child in children:  # on error here or in a sibling: stop the rest
                if child.poll() is None:
                    child.kill()
                    child.wait()
        concat_videos(segments, path)
    return len(frames)


def _render_part(job_path: str) -> None:
    """Child process of `render_video`: render and encode one part of the frame range."""
    job = pickle.loads(Path(job_path).read_bytes())
    parent_pid, clip, parts, camera, settings, size, fps, frames, out = job
    # A cancelled job's process is terminated without running its cleanup: die with it.
    die_with_parent()
    if os.getppid() != parent_pid:  # it died before the line above
        sys.exit(1)
    with (
        CharacterScene(clip, parts, *size) as scene,
        VideoWriter(out, fps, size, crf=settings.crf, preset=settings.preset) as video,
    ):
        _write_frames(scene, camera, frames, video, settings)


def contact_sheet_frames(shots: np.ndarray) -> list[tuple[int, str, int]]:
    """(shot, "start" | "middle", clip frame) for every shot, in order."""
    out = []
    for k, (a, b) in enumerate(shots):
        out.append((k, "start", int(a)))
        out.append((k, "middle", int((a + b) // 2)))
    return out


def render_contact_sheet(
    scene: CharacterScene, camera: PreviewCamera, path: str | Path, settings: PreviewSettings = PreviewSettings()
) -> tuple[int, int]:
    """Write the contact sheet PNG: two tiles per shot (start, middle), two shots per row when
    there are several; each tile labelled. Returns (columns, rows)."""
    tiles = contact_sheet_frames(camera.shots)
    tw, th = even_size(camera.aspect, settings.tile_height_px)
    label_h = max(14, th // 8)
    cols = 2 if len(camera.shots) == 1 else 4
    rows = math.ceil(len(tiles) / cols)
    pad = 4
    sheet = Image.new("RGB", (cols * (tw + pad) + pad, rows * (th + label_h + pad) + pad), (245, 245, 245))
    draw = ImageDraw.Draw(sheet)
    font = _font(max(10, label_h - 4))
    dt = scene.clip.frame_time_s
    for i, (shot, which, frame) in enumerate(tiles):
        image = Image.fromarray(scene.render(frame, camera))
        if image.size != (tw, th):
            image = image.resize((tw, th), Image.Resampling.BILINEAR)
        x = pad + (i % cols) * (tw + pad)
        y = pad + (i // cols) * (th + label_h + pad)
        sheet.paste(image, (x, y))
        draw.rectangle([x, y + th, x + tw - 1, y + th + label_h - 1], fill=shot_rgb(shot))
        draw.text(
            (x + 4, y + th + 1), f"shot {shot + 1} {which}  frame {frame}  {frame * dt:.2f} s", fill=(255, 255, 255), font=font
        )
    sheet.save(path, format="PNG")
    return cols, rows


def render_preview(
    clip: MotionClip,
    parts: BodyPartMap,
    camera: PreviewCamera,
    video_path: str | Path | None,
    sheet_path: str | Path | None,
    settings: PreviewSettings = PreviewSettings(),
) -> dict[str, float]:
    """Write the preview mp4 and/or the contact sheet PNG; returns timings in ms
    ("preview_video", "contact_sheet")."""
    if len(camera.position_m) != clip.frame_count:
        raise ValueError(f"camera has {len(camera.position_m)} frames, clip {clip.frame_count}")
    timings: dict[str, float] = {}
    w, h = even_size(camera.aspect, settings.height_px)
    t = time.perf_counter()
    with CharacterScene(clip, parts, w, h) as scene:
        timings["preview_setup"] = (time.perf_counter() - t) * 1e3
        if video_path is not None:
            t = time.perf_counter()
            render_video(scene, camera, video_path, settings)
            timings["preview_video"] = (time.perf_counter() - t) * 1e3
        if sheet_path is not None:
            t = time.perf_counter()
            render_contact_sheet(scene, camera, sheet_path, settings)
            timings["contact_sheet"] = (time.perf_counter() - t) * 1e3
    return timings


if __name__ == "__main__":
    _render_part(sys.argv[1])
