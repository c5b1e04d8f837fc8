"""The monitors' pictures as the front serves them: one render however many viewers.

A picture (render/snapshots.py) is asked of the worker holding its session by (session, query).
The hub keeps the newest picture of each and the render in flight: a viewer that asks while one
is being made waits for it, and one that asks within `max_age_s` of the last gets that one. So
many dashboards watching one session cost one render per period, not one per viewer. A live
stream (`stream`) is a loop of such asks at its rate; it holds nothing but its place in the
`streams` count, which its `finally` gives back when the viewer goes away. The top view never
changes: it is kept until its entry is pushed out (the hub keeps MAX_ENTRIES pictures, the least
recently asked dropped first). With keys on, each tenant's live streams are also counted against
its share (`ServerSettings.tenant_max_live_views`), so one tenant's viewers cannot hold every place.
"""

from __future__ import annotations

import asyncio
import time
from collections import OrderedDict
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass

from camdirector.errors import DirectorError, exhausted
from camdirector.front.metrics import Metrics
from camdirector.front.router import SessionRouter
from camdirector.infra.channels import ViewQuery, decode_view

MAX_ENTRIES = 256  # pictures kept (a few per watched session)
RENDER_TIMEOUT_S = 10.0  # a render taking longer answers UNAVAILABLE (503)
MAX_STREAMS = 64  # live streams at once, all sessions together; more answer 429
MAX_STREAM_FPS = 10.0  # a live stream's highest rate, frames per second
KEEPALIVE_S = 1.0  # a stream whose picture does not change repeats it this often


@dataclass(frozen=True)
class View:
    """One picture and what the render process said of it."""

    image: bytes
    media_type: str
    frame: int | None  # the session frame it shows; None for the top view or a placeholder
    placeholder: str | None  # why it is a placeholder, if it is one
    note: str | None  # what its banner says (a world without geometry), if it has one
    render_ms: float  # in the render process
    bounds_m: list[float] | None  # the top view's world rectangle [x0, z0, x1, z1], m
    made_s: float  # when the hub got it, on its clock
    labels: list[str]  # the names labelled on a camera view, nearest last (geometry/labels.py)


class ViewHub:
    def __init__(self, router: SessionRouter, metrics: Metrics, clock: Callable[[], float] = time.monotonic):
        self.router = router
        self.metrics = metrics
        self.clock = clock
        # Keyed by the asking tenant too: a picture kept for one tenant is never another's answer.
        self._views: OrderedDict[tuple[str, str, ViewQuery], View] = OrderedDict()
        self._rendering: dict[tuple[str, str, ViewQuery], asyncio.Future] = {}
        self.streams = 0
        self.streams_by_tenant: dict[str, int] = {}
        self._closing = asyncio.Event()

    async def get(self, session_id: str, query: ViewQuery, max_age_s: float, tenant: str = "default") -> View:
        """The picture, at most max_age_s old (math.inf: any kept one), of `tenant`'s session.
        Raises DirectorError (NOT_FOUND for another tenant's session, as for a missing one)."""
        key = (tenant, session_id, query)
        self.metrics.labelled(self.metrics.view_requests, query.shot).inc()
        kept = self._views.get(key)
        if kept is not None and self.clock() - kept.made_s <= max_age_s:
            self._views.move_to_end(key)
            return kept
        pending = self._rendering.get(key)
        if pending is None:
            pending = self._rendering[key] = asyncio.ensure_future(self._render(key))
        return await asyncio.shield(pending)

    async def _render(self, key: tuple[str, str, ViewQuery]) -> View:
        tenant, session_id, query = key
        try:
            self.metrics.view_renders.inc()
            header, image = decode_view(await self.router.view(session_id, query.to_json(), RENDER_TIMEOUT_S, tenant))
            view = View(
                image,
                header["media_type"],
                header["frame"],
                header["placeholder"],
                header["note"],
                header["render_ms"],
                header["bounds_m"],
                self.clock(),
                header["labels"],
            )
            self._views[key] = view
            self._views.move_to_end(key)
            while len(self._views) > MAX_ENTRIES:
                self._views.popitem(last=False)
            return view
        except DirectorError:
            self._views.pop(key, None)  # a closed session's pictures go with it
            raise
        finally:
            self._rendering.pop(key, None)

    def check_stream_room(self, tenant: str) -> None:
        """RESOURCE_EXHAUSTED when MAX_STREAMS live streams are open already, or (with keys on)
        `tenant` holds its share of them."""
        if self.streams >= MAX_STREAMS:
            raise exhausted(f"the server serves its maximum of {MAX_STREAMS} live views")
        share = self.router.settings.tenant_max_live_views
        if self.router.guard.enabled and self.streams_by_tenant.get(tenant, 0) >= share:
            raise exhausted(f"tenant {tenant!r} has its maximum of {share} live views open on this node; close one first")

    async def stream(
        self, session_id: str, query: ViewQuery, fps: float, first: View, tenant: str = "default"
    ) -> AsyncIterator[View]:
        """A live view at `fps`: `first`, then each new picture (the same one again after
        KEEPALIVE_S without change), until the session ends, the hub closes or the viewer goes
        away (the caller stops iterating, or is cancelled). Counted in `streams` while it runs."""
        period_s = 1.0 / fps
        self.streams += 1
        self.streams_by_tenant[tenant] = self.streams_by_tenant.get(tenant, 0) + 1
        self.metrics.view_streams.set(self.streams)
        try:
            view = first
            tick_s = sent_s = self.clock()
            yield view
            while not self._closing.is_set():
                tick_s = max(tick_s + period_s, self.clock() - period_s)  # fallen behind: no burst to catch up
                try:
                    await asyncio.wait_for(self._closing.wait(), max(tick_s - self.clock(), 0.0))
                    return
                except TimeoutError:
                    pass
                try:
                    fresh = await self.get(session_id, query, period_s / 2, tenant)
                except DirectorError:
                    return  # the session ended (or its worker): the stream ends with it
                if fresh.frame != view.frame or fresh.placeholder != view.placeholder or self.clock() - sent_s >= KEEPALIVE_S:
                    view, sent_s = fresh, self.clock()
                    yield view
        finally:
            self.streams -= 1
            self.streams_by_tenant[tenant] -= 1
            if not self.streams_by_tenant[tenant]:
                del self.streams_by_tenant[tenant]
            self.metrics.view_streams.set(self.streams)

    def close(self) -> None:
        """Ends every live stream (the server is stopping: an endless response would hold it)."""
        self._closing.set()
