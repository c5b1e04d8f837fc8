"""The checkpoint store's calls, off the frame path: one thread per session table makes them in
the order they were given, and a caller waits for a call's result only up to a budget.

A store that answers (Redis on its usual sub-millisecond, a local disk) answers within the budget,
so a write's result is known before the frame's answer leaves, as if it were made inline: the
ownership fence holds (checkpointing.py). A store that hangs (Redis paused, a network that drops
packets) costs the first frame that meets it at most the budget; while the thread is still inside a
call that has run past the budget (`stuck`), nobody waits at all: the session goes on, its
checkpoint marked behind (checkpointing.py writes it again whole once the store answers). Calls
already given are still made, in order, when the store answers again, so nothing is written out of
order. Whether the store answers again is learnt by `probe`, made by the thread itself while the
last call failed.

A store that cannot hang (a folder on a local disk: `CheckpointStore.may_hang` False) is written
inline instead (`InlineWriter`, the same interface): handing each call to a thread costs a frame
about 0.1 ms (load_tests/checkpoint_bench.py), more than the write.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import threading
import time
from collections.abc import Callable
from typing import Any

from camdirector.worker.checkpoint_stores import CheckpointError

log = logging.getLogger("camdirector.checkpoints")

PROBE_EVERY_S = 0.5  # while the store fails, how often the thread asks whether it answers again, s
CLOSE_WAIT_S = 2.0  # on close, how long calls still queued may take before they are abandoned, s


class Pending:
    """One call's result, set by the writer's thread."""

    __slots__ = ("_done", "_error", "_value")

    def __init__(self) -> None:
        self._done = threading.Event()
        self._value: Any = None
        self._error: CheckpointError | None = None

    def result(self, timeout_s: float) -> Any:
        """The call's value; CheckpointError when it failed; TimeoutError when it has not
        finished within `timeout_s` (it will still be made)."""
        if not self._done.wait(timeout_s):
            raise TimeoutError
        if self._error is not None:
            raise self._error
        return self._value


class Made:
    """A call already made (InlineWriter's): Pending's `result`, with no event to wait on (making
    a threading.Event cost a frame's append more than its write)."""

    __slots__ = ("_error", "_value")

    def __init__(self, value: Any, error: CheckpointError | None) -> None:
        self._value = value
        self._error = error

    def result(self, timeout_s: float) -> Any:
        if self._error is not None:
            raise self._error
        return self._value


class InlineWriter:
    """Makes each call at once, on the caller's thread (module docstring). Always `healthy`: a
    failed write is simply tried again at its session's next retry."""

    healthy = True

    def call(self, fn: Callable[..., Any], *args: Any) -> Made:
        try:
            return Made(fn(*args), None)
        except CheckpointError as exc:
            return Made(None, exc)

    def stuck(self, budget_s: float) -> bool:
        return False

    def close(self) -> None:
        pass


class CheckpointWriter:
    """Makes a store's calls on a thread of its own, in order (module docstring). `probe` is
    called on that thread while the last call failed (the store's cheapest call: True when it
    answers)."""

    def __init__(self, probe: Callable[[], bool], clock: Callable[[], float] = time.monotonic) -> None:
        self._probe = probe
        self._clock = clock
        self._calls: queue.SimpleQueue[tuple[Callable[..., Any], tuple[Any, ...], Pending] | None] = queue.SimpleQueue()
        self._busy_since: float | None = None  # when the call being made began (clock), None when idle
        self.healthy = True  # the last call (or probe) reached the store
        self._thread = threading.Thread(target=self._run, name="checkpoint-writer", daemon=True)
        self._thread.start()

    def call(self, fn: Callable[..., Any], *args: Any) -> Pending:
        """`fn(*args)` made on the writer's thread after every call given before it."""
        pending = Pending()
        self._calls.put((fn, args, pending))
        return pending

    def stuck(self, budget_s: float) -> bool:
        """Whether the thread has been inside one call for longer than `budget_s`: a caller then
        does not wait (module docstring)."""
        since = self._busy_since
        return since is not None and self._clock() - since > budget_s

    def close(self) -> None:
        """Makes the calls already given (for at most CLOSE_WAIT_S), then ends the thread."""
        self._calls.put(None)
        self._thread.join(CLOSE_WAIT_S)
        if self._thread.is_alive():
            log.warning("checkpoint writes still queued after %.0f s at close were abandoned", CLOSE_WAIT_S)

    def _run(self) -> None:
        while True:
            try:
                item = self._calls.get(timeout=PROBE_EVERY_S) if not self.healthy else self._calls.get()
            except queue.Empty:
                with contextlib.suppress(CheckpointError):  # still down: `healthy` stays False
                    self._make(self._probe_once)
                continue
            if item is None:
                return
            fn, args, pending = item
            try:
                pending._value = self._make(fn, *args)
            except CheckpointError as exc:
                pending._error = exc
            pending._done.set()

    def _make(self, fn: Callable[..., Any], *args: Any) -> Any:
        self._busy_since = self._clock()
        try:
            value = fn(*args)
        except CheckpointError:
            self.healthy = False
            raise
        finally:
            self._busy_since = None
        self.healthy = True
        return value

    def _probe_once(self) -> None:
        if not self._probe():
            raise CheckpointError("the checkpoint store does not answer")
