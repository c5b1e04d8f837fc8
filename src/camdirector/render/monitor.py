"""A worker's handle on its render process (render/main.py): the pictures of its sessions'
monitors (snapshots.py), made off the frame path.

moderngl holds the GIL through every GL call, its readback included (moderngl pull request 723,
still open, would release it), so a render thread would stop a worker's frames for as long as a
render takes. A worker therefore starts one render process, on the first view it is asked for,
and talks to it over the process's stdin and stdout (infra/channels.py: length-prefixed pickles).
On the worker's side (`Monitor`), the main thread only takes the snapshot
(snapshots.render_job) and queues it; a writer thread sends it (and, once per session, the meshes),
a reader thread takes the picture back and hands it to the caller's `reply`.
Each reply body is a view, framed by infra/channels.py (`encode_view`).
"""

from __future__ import annotations

import logging
import os
import queue
import subprocess
import sys
import threading
from collections.abc import Callable
from typing import Any

from camdirector.infra.channels import read_message, write_message
from camdirector.render.snapshots import RenderJob, SceneGeometry

log = logging.getLogger("camdirector.monitor")

OK, UNAVAILABLE = 0, 14  # gRPC status codes, as the worker's replies carry them

Reply = Callable[[int, bytes], None]  # (status, body): status OK with a view, else an error message


class Monitor:
    """A worker's handle on its render process (module docstring), started on the first submit and
    again after it died. Thread-safe: submit and forget may come from any thread."""

    def __init__(self, python: str = sys.executable):
        self.python = python
        self._lock = threading.Lock()
        self._proc: subprocess.Popen[bytes] | None = None  # set by the writer thread once started
        self._outbox: queue.SimpleQueue[tuple[Any, ...]] | None = None  # None: no process (not yet, or it died)
        self._sent: set[str] = set()  # sessions whose meshes the process holds
        self._waiting: dict[int, Reply] = {}  # job number -> its reply
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
                threading.Thread(target=self._send_forever, args=(self._outbox,), name="monitor-writer", daemon=True).start()
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
                if self._outbox is not None:  # else the process died, and the meshes with it
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
        outbox.put(("close", done))  # the writer closes stdin (the process exits) and waits for it
        if not done.wait(timeout=10.0):
            log.error("the view renderer did not stop")

    def _send_forever(self, outbox: queue.SimpleQueue[tuple[Any, ...]]) -> None:
        """The writer thread of one render process: starts it, then sends what is queued."""
        env = dict(os.environ)
        env.setdefault("LP_NUM_THREADS", "1")  # llvmpipe's rasterizer threads: one is plenty at monitor sizes
        proc = subprocess.Popen(
            [self.python, "-m", "camdirector.render.main"], stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env
        )
        assert proc.stdin is not None and proc.stdout is not None  # both asked for as pipes
        self._proc = proc
        reader = threading.Thread(target=self._receive_forever, args=(proc, outbox), name="monitor-reader", daemon=True)
        reader.start()
        alive, closing = True, None
        while True:  # until told to close, or that the process is gone
            message = outbox.get()
            if message[0] == "close":
                closing = message[1]
                break
            if message[0] == "gone":  # it died: the reader has answered what waited
                break
            if not alive:
                continue
            try:
                if message[0] == "geometry":
                    message = ("geometry", message[1], message[2]())
                write_message(proc.stdin, message)
            except (BrokenPipeError, ValueError, OSError):
                alive = False  # it died: the reader answers what waits, then says "gone"
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

    def _receive_forever(self, proc: subprocess.Popen[bytes], outbox: queue.SimpleQueue[tuple[Any, ...]]) -> None:
        stdout = proc.stdout
        assert stdout is not None  # a pipe (_send_forever)
        while (message := read_message(stdout)) is not None:
            number, status, body = message
            with self._lock:
                reply = self._waiting.pop(number, None)
            if reply is not None:
                self._answer(reply, status, body)
        proc.wait()
        with self._lock:
            waiting, self._waiting = self._waiting, {}
            if self._outbox is outbox:  # died on its own: the next submit starts another
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
