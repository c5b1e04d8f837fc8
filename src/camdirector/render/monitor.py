"""A worker's render process: the pictures of its sessions' monitors (views.py), made off the
frame path.

moderngl holds the GIL through every GL call, its readback included (moderngl pull request 723,
still open, would release it), so a render thread would stop a worker's frames for as long as a
render takes. A worker therefore starts one render process, on the first view it is asked for,
and talks to it over the process's stdin and stdout: length-prefixed pickles, both ends being
this module. On the worker's side (`Monitor`), the main thread only takes the snapshot
(views.render_job) and queues it; a writer thread sends it (and, once per session, the meshes),
a reader thread takes the picture back and hands it to the caller's `reply`. The render process
runs under Linux's SCHED_IDLE policy (elsewhere at nice RENDER_NICENESS), with llvmpipe on one
thread: it gets a core only when no frame wants it, so a busy machine starves the monitors, never
the frames.

In the render process (`Painter`): one EGL context; per session its meshes and one
OffscreenRenderer per picture size (all sharing the context), the least recently used released
beyond RENDERERS_KEPT; a session's top view made once and kept until the session is forgotten.
It exits when the worker closes its stdin (the worker stopped or died).

Each reply body is a view (`encode_view`): a 4-byte length, a JSON header (the frame shown, the
placeholder's reason if any, the render time, the media type, and the top view's world bounds),
then the image.
"""
from __future__ import annotations

import io
import logging
import os
import pickle
import queue
import struct
import subprocess
import sys
import textwrap
import threading
import time
from collections import OrderedDict
from collections.abc import Callable

import numpy as np
import orjson

from camdirector.render.snapshots import (
    TOP_VIEW_LONG_SIDE_PX,
    RenderJob,
    SceneGeometry,
    rigid_matrices,
)

log = logging.getLogger("camdirector.monitor")

RENDER_NICENESS = 10        # where SCHED_IDLE is missing: added to the render process's niceness
RENDERERS_KEPT = 8          # OffscreenRenderers kept per render process (sessions x picture sizes)
JPEG_QUALITY = 80           # [1, 95]: 320x180 pictures of 5-15 KB
TOP_VIEW_MARGIN_M = 1.0     # world kept around the static geometry in the top view, m
PLACEHOLDER_RGB = (58, 60, 66)
OK, UNAVAILABLE = 0, 14     # gRPC status codes, as the worker's replies carry them
_LENGTH = struct.Struct("!Q")
_VIEW_HEADER = struct.Struct("!I")


# -- the view's bytes -------------------------------------------------------------------------

def encode_view(header: dict, image: bytes) -> bytes:
    meta = orjson.dumps(header)
    return _VIEW_HEADER.pack(len(meta)) + meta + image


def decode_view(body: bytes) -> tuple[dict, bytes]:
    """(header, image) of a view's bytes (module docstring)."""
    (length,) = _VIEW_HEADER.unpack_from(body)
    start = _VIEW_HEADER.size
    return orjson.loads(body[start:start + length]), body[start + length:]


def _write(stream, message) -> None:
    data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_LENGTH.pack(len(data)) + data)
    stream.flush()


def _read(stream):
    """The next message, or None at end of file."""
    head = stream.read(_LENGTH.size)
    if len(head) < _LENGTH.size:
        return None
    (length,) = _LENGTH.unpack(head)
    data = stream.read(length)
    if len(data) < length:
        return None
    return pickle.loads(data)  # noqa: S301 - both ends are this module, over a private pipe


# -- the worker's side ------------------------------------------------------------------------

Reply = Callable[[int, bytes], None]   # (status, body): status OK with a view, else an error message


class Monitor:
    """A worker's handle on its render process (module docstring), started on the first submit and
    again after it died. Thread-safe: submit and forget may come from any thread."""

    def __init__(self, python: str = sys.executable):
        self.python = python
        self._lock = threading.Lock()
        self._proc: subprocess.Popen | None = None     # set by the writer thread once started
        self._outbox: queue.SimpleQueue | None = None  # None: no process (not yet, or it died)
        self._sent: set[str] = set()                # sessions whose meshes the process holds
        self._waiting: dict[int, Reply] = {}        # job number -> its reply
        self._numbers = iter(range(1, 1 << 62))

    def submit(self, job: RenderJob, geometry: Callable[[], SceneGeometry], reply: Reply) -> None:
        """Queues the picture of `job`; `reply` is called once, from another thread, with it or
        with UNAVAILABLE and why. `geometry` makes the session's meshes, called (on the writer
        thread) only when the process does not hold them yet. Never blocks: even the process is
        started on the writer thread."""
        with self._lock:
            if self._outbox is None:
                self._outbox = queue.SimpleQueue()
                self._sent = set()
                threading.Thread(target=self._send_forever, args=(self._outbox,), name="monitor-writer",
                                 daemon=True).start()
            number = next(self._numbers)
            self._waiting[number] = reply
            if job.session_id not in self._sent:
                self._sent.add(job.session_id)
                self._outbox.put(("geometry", job.session_id, geometry))
            self._outbox.put(("render", number, job))

    def forget(self, session_id: str) -> None:
        """The session ended: the process releases its renderers and meshes."""
        with self._lock:
            if session_id in self._sent:
                self._sent.discard(session_id)
                self._outbox.put(("forget", session_id))

    @property
    def pid(self) -> int | None:
        """The render process's pid while it runs (for tests and tools)."""
        proc = self._proc
        return proc.pid if proc is not None and proc.poll() is None else None

    def close(self) -> None:
        """Stops the render process (its pending views answer UNAVAILABLE)."""
        with self._lock:
            outbox, self._outbox = self._outbox, None
        if outbox is None:
            return
        done = threading.Event()
        outbox.put(("close", done))   # the writer closes stdin (the process exits) and waits for it
        if not done.wait(timeout=10.0):
            log.error("the view renderer did not stop")

    def _send_forever(self, outbox: queue.SimpleQueue) -> None:
        """The writer thread of one render process: starts it, then sends what is queued."""
        env = dict(os.environ)
        env.setdefault("LP_NUM_THREADS", "1")   # llvmpipe's rasterizer threads: one is plenty at monitor sizes
        proc = subprocess.Popen([self.python, "-m", "camdirector.render.monitor"],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)
        self._proc = proc
        reader = threading.Thread(target=self._receive_forever, args=(proc, outbox), name="monitor-reader",
                                  daemon=True)
        reader.start()
        alive, closing = True, None
        while True:   # until told to close, or that the process is gone
            message = outbox.get()
            if message[0] == "close":
                closing = message[1]
                break
            if message[0] == "gone":   # it died: the reader has answered what waited
                break
            if not alive:
                continue
            try:
                if message[0] == "geometry":
                    message = ("geometry", message[1], message[2]())
                _write(proc.stdin, message)
            except (BrokenPipeError, ValueError, OSError):
                alive = False   # it died: the reader answers what waits, then says "gone"
        try:
            proc.stdin.close()
        except OSError:
            pass
        try:
            proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            proc.kill()
        reader.join(timeout=5.0)
        if closing is not None:
            closing.set()

    def _receive_forever(self, proc: subprocess.Popen, outbox: queue.SimpleQueue) -> None:
        while (message := _read(proc.stdout)) is not None:
            number, status, body = message
            with self._lock:
                reply = self._waiting.pop(number, None)
            if reply is not None:
                self._answer(reply, status, body)
        proc.wait()
        with self._lock:
            waiting, self._waiting = self._waiting, {}
            if self._outbox is outbox:   # died on its own: the next submit starts another
                self._outbox = None
                outbox.put(("gone",))
            if self._proc is proc:
                self._proc = None
        if waiting:
            log.error("the view renderer (pid %d) exited with code %s", proc.pid, proc.returncode)
        for reply in waiting.values():
            self._answer(reply, UNAVAILABLE, f"the view renderer exited (code {proc.returncode}); ask again".encode())

    @staticmethod
    def _answer(reply: Reply, status: int, body: bytes) -> None:
        try:
            reply(status, body)
        except Exception:  # the asker went away (the front's socket closed): the next view goes on
            log.exception("answering a view")


# -- the render process -----------------------------------------------------------------------

class Painter:
    """The render process's state (module docstring)."""

    def __init__(self):
        self._ctx = None
        self._geometry: dict[str, SceneGeometry] = {}
        self._renderers: OrderedDict[tuple[str, int, int], object] = OrderedDict()
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
        header = {"frame": job.frame, "placeholder": job.placeholder, "note": job.note, "bounds_m": None}
        if job.query.shot == "top":
            image, header["bounds_m"], header["placeholder"] = self._top_view(job.session_id)
            media_type = "image/png"
        else:
            fmt = job.query.image_format
            if job.placeholder is None:
                pixels = self._camera_view(job)
                if job.note is not None:
                    pixels = banner(pixels, job.note)
            else:
                pixels = placeholder_pixels(*job.size_px, job.placeholder)
            image, media_type = encode_image(pixels, fmt), f"image/{fmt}"
        header.update(media_type=media_type, render_ms=round((time.perf_counter() - t0) * 1e3, 3))
        return encode_view(header, image)

    def _context(self):
        if self._ctx is None:
            import moderngl  # only the render process loads GL

            self._ctx = moderngl.create_standalone_context(backend="egl")
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
        return renderer.render(job.pose, job.lens)

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
            return encode_image(placeholder_pixels(TOP_VIEW_LONG_SIDE_PX, TOP_VIEW_LONG_SIDE_PX // 2, reason), "png"), \
                None, reason
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
    os.dup2(2, 1)   # whatever a library prints goes to stderr, never into the replies
    try:   # runs only on a core nothing else wants (its threads, llvmpipe's included, inherit it)
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):   # not Linux
        os.nice(RENDER_NICENESS)
    inbox = sys.stdin.buffer
    painter = Painter()
    try:
        while (message := _read(inbox)) is not None:
            if message[0] == "geometry":
                painter.add_session(message[1], message[2])
            elif message[0] == "forget":
                painter.forget(message[1])
            else:
                _, number, job = message
                try:
                    _write(channel, (number, OK, painter.render(job)))
                except Exception as exc:  # EGL missing, a bad mesh: this view fails, the process goes on
                    log.exception("view of session %s", job.session_id)
                    _write(channel, (number, UNAVAILABLE, f"the view could not be rendered: {exc}".encode()))
    finally:
        painter.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
