"""The render process's main loop: the monitors' pictures of one worker's sessions.

It runs under Linux's SCHED_IDLE policy (elsewhere at nice RENDER_NICENESS), with llvmpipe on one
thread: it gets a core only when no frame wants it, so a busy machine starves the monitors, never
the frames. One EGL context (`Painter`); per session its meshes and one OffscreenRenderer per
picture size (all sharing the context), the least recently used released beyond RENDERERS_KEPT;
a session's top view made once and kept until the session is forgotten. It reads the worker's
messages on stdin and answers on stdout (infra/channels.py), and exits when the worker closes its
stdin (the worker stopped or died). The worker's end is render/monitor.py.
"""

from __future__ import annotations

import io
import logging
import os
import sys
import textwrap
import time
from collections import OrderedDict
from typing import TYPE_CHECKING

import numpy as np

from camdirector.geometry.labels import draw_labels
from camdirector.infra.channels import encode_view, read_message, write_message
from camdirector.render.monitor import OK, UNAVAILABLE
from camdirector.render.snapshots import TOP_VIEW_LONG_SIDE_PX, RenderJob, SceneGeometry, label_heads, rigid_matrices

if TYPE_CHECKING:  # imported where it is used: only the render process loads GL
    import moderngl

    from camdirector.geometry.render import OffscreenRenderer

log = logging.getLogger("camdirector.render")

RENDER_NICENESS = 10  # where SCHED_IDLE is missing: added to the render process's niceness
RENDERERS_KEPT = 8  # OffscreenRenderers kept per render process (sessions x picture sizes)
JPEG_QUALITY = 80  # [1, 95]: 320x180 pictures of 5-15 KB
TOP_VIEW_MARGIN_M = 1.0  # world kept around the static geometry in the top view, m
PLACEHOLDER_RGB = (58, 60, 66)


class Painter:
    """The render process's state (module docstring)."""

    def __init__(self) -> None:
        self._ctx: moderngl.Context | None = None
        self._geometry: dict[str, SceneGeometry] = {}
        self._renderers: OrderedDict[tuple[str, int, int], OffscreenRenderer] = OrderedDict()
        self._top: dict[str, tuple[bytes, list[float] | None, str | None]] = {}

    def add_session(self, session_id: str, geometry: SceneGeometry) -> None:
        self.forget(session_id)
        self._geometry[session_id] = geometry

    def forget(self, session_id: str) -> None:
        self._geometry.pop(session_id, None)
        self._top.pop(session_id, None)
        for key in [k for k in self._renderers if k[0] == session_id]:
            self._renderers.pop(key).release()

    def close(self) -> None:
        for session_id in list(self._geometry):
            self.forget(session_id)
        if self._ctx is not None:
            self._ctx.release()

    def render(self, job: RenderJob) -> bytes:
        """The view's bytes (encode_view) for one job."""
        t0 = time.perf_counter()
        header: dict[str, object] = {
            "frame": job.frame,
            "placeholder": job.placeholder,
            "note": job.note,
            "bounds_m": None,
            "labels": [],
        }
        if job.query.shot == "top":
            image, header["bounds_m"], header["placeholder"] = self._top_view(job.session_id)
            media_type = "image/png"
        else:
            fmt = job.query.image_format
            if job.placeholder is None:
                pixels, header["labels"] = self._labelled(job, self._camera_view(job))
                if job.note is not None:
                    pixels = banner(pixels, job.note)
            else:
                pixels = placeholder_pixels(*job.size_px, job.placeholder)
            image, media_type = encode_image(pixels, fmt), f"image/{fmt}"
        header.update(media_type=media_type, render_ms=round((time.perf_counter() - t0) * 1e3, 3))
        return encode_view(header, image)

    def _context(self) -> moderngl.Context:
        if self._ctx is None:
            from camdirector.geometry.gl_context import egl_context  # only the render process loads GL

            self._ctx = egl_context()
        return self._ctx

    def _camera_view(self, job: RenderJob) -> np.ndarray:
        from camdirector.geometry.render import OffscreenRenderer

        width, height = job.size_px
        key = (job.session_id, width, height)
        renderer = self._renderers.get(key)
        if renderer is None:
            renderer = OffscreenRenderer(width, height, context=self._context())
            for part in self._geometry[job.session_id].parts:
                renderer.add_mesh(part.part_id, part.vertices, part.faces, part.rgb, checker_m=part.checker_m)
            self._renderers[key] = renderer
            while len(self._renderers) > RENDERERS_KEPT:
                self._renderers.popitem(last=False)[1].release()
        self._renderers.move_to_end(key)
        if job.moving_ids:
            renderer.set_transforms(list(job.moving_ids), rigid_matrices(job))
        assert job.pose is not None  # a job without a pose has a placeholder instead (snapshots.py)
        return renderer.render(job.pose, job.lens)

    def _labelled(self, job: RenderJob, pixels: np.ndarray) -> tuple[np.ndarray, list[str]]:
        """The camera view with its targets' name labels, and the texts of those drawn, nearest last."""
        labels = self._geometry[job.session_id].labels
        assert job.pose is not None  # a camera view (render)
        bar_rgb = (255 * np.array([label.rgb for label in labels]).reshape(-1, 3)).round().astype(np.uint8)
        texts = [label.text for label in labels]
        pixels, placed = draw_labels(pixels, job.pose, job.lens, label_heads(job, labels), texts, bar_rgb)
        return pixels, [p.text for p in placed]

    def _top_view(self, session_id: str) -> tuple[bytes, list[float] | None, str | None]:
        """(PNG, world bounds [x0, z0, x1, z1] m, placeholder reason), made once per session."""
        cached = self._top.get(session_id)
        if cached is None:
            cached = self._top[session_id] = self._draw_top_view(self._geometry[session_id])
        return cached

    def _draw_top_view(self, geometry: SceneGeometry) -> tuple[bytes, list[float] | None, str | None]:
        from camdirector.geometry.render import OffscreenRenderer, top_down_matrix

        world = [p for p in geometry.parts if not p.moving]
        if not world:
            reason = "no world geometry: the scene has no static object and no level"
            return (
                encode_image(placeholder_pixels(TOP_VIEW_LONG_SIDE_PX, TOP_VIEW_LONG_SIDE_PX // 2, reason), "png"),
                None,
                reason,
            )
        vertices = np.concatenate([p.vertices for p in world]).astype(np.float64)
        low, high = vertices.min(axis=0) - TOP_VIEW_MARGIN_M, vertices.max(axis=0) + TOP_VIEW_MARGIN_M
        extent_x, extent_z = high[0] - low[0], high[2] - low[2]
        scale = TOP_VIEW_LONG_SIDE_PX / max(extent_x, extent_z)
        width, height = max(int(round(extent_x * scale)), 16), max(int(round(extent_z * scale)), 16)
        # Far fog: the picture is seen from above at any height, and must not fade.
        with OffscreenRenderer(width, height, fog_start_m=1.0e6, fog_end_m=2.0e6, context=self._context()) as renderer:
            for part in world:
                renderer.add_mesh(part.part_id, part.vertices, part.faces, part.rgb, checker_m=part.checker_m)
            eye = np.array([0.5 * (low[0] + high[0]), high[1], 0.5 * (low[2] + high[2])])
            pixels = renderer.render_view(top_down_matrix((low[0], high[0]), (low[2], high[2]), (low[1], high[1])), eye)
        return encode_image(pixels, "png"), [float(low[0]), float(low[2]), float(high[0]), float(high[2])], None


def encode_image(pixels: np.ndarray, fmt: str) -> bytes:
    """JPEG or PNG bytes of (h, w, 3) uint8 pixels."""
    from PIL import Image

    out = io.BytesIO()
    if fmt == "jpeg":
        Image.fromarray(pixels, "RGB").save(out, format="JPEG", quality=JPEG_QUALITY)
    else:
        Image.fromarray(pixels, "RGB").save(out, format="PNG")
    return out.getvalue()


def placeholder_pixels(width: int, height: int, reason: str) -> np.ndarray:
    """(height, width, 3) uint8: a dark card that says why there is no picture."""
    from PIL import Image, ImageDraw

    card = Image.new("RGB", (width, height), PLACEHOLDER_RGB)
    draw = ImageDraw.Draw(card)
    lines = textwrap.wrap(reason, width=max(int(width / 7), 8))
    y = max((height - 14 * len(lines)) // 2, 2)
    for line in lines:
        draw.text((6, y), line, fill=(225, 225, 225))
        y += 14
    return np.asarray(card)


def banner(pixels: np.ndarray, text: str) -> np.ndarray:
    """(h, w, 3) uint8: the picture with `text` on a dark band across its top."""
    from PIL import Image, ImageDraw

    card = Image.fromarray(pixels, "RGB")
    draw = ImageDraw.Draw(card)
    lines = textwrap.wrap(text, width=max(int(card.width / 7), 8))
    draw.rectangle((0, 0, card.width, 6 + 14 * len(lines)), fill=PLACEHOLDER_RGB)
    for k, line in enumerate(lines):
        draw.text((6, 3 + 14 * k), line, fill=(225, 225, 225))
    return np.asarray(card)


def main() -> int:
    """The render process: answers the worker until it closes stdin."""
    channel = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # whatever a library prints goes to stderr, never into the replies
    try:  # runs only on a core nothing else wants (its threads, llvmpipe's included, inherit it)
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):  # not Linux
        os.nice(RENDER_NICENESS)
    inbox = sys.stdin.buffer
    painter = Painter()
    try:
        while (message := read_message(inbox)) is not None:
            if message[0] == "geometry":
                painter.add_session(message[1], message[2])
            elif message[0] == "forget":
                painter.forget(message[1])
            else:
                _, number, job = message
                try:
                    write_message(channel, (number, OK, painter.render(job)))
                except Exception as exc:  # EGL missing, a bad mesh: this view fails, the process goes on
                    log.exception("view of session %s", job.session_id)
                    write_message(channel, (number, UNAVAILABLE, f"the view could not be rendered: {exc}".encode()))
    finally:
        painter.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
