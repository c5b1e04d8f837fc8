"""Prometheus metrics of the front process (served at /metrics on the HTTP address)."""

from __future__ import annotations

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram

# 50 us .. 1 s: per-frame work is sub-millisecond when healthy.
_SECONDS_BUCKETS = (5e-5, 1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2, 2e-2, 5e-2, 0.1, 0.25, 1.0)


class Metrics:
    def __init__(self) -> None:
        self._children: dict[tuple, object] = {}
        self.registry = CollectorRegistry()
        r = self.registry
        self.sessions = Gauge("camdirector_sessions", "Open sessions", registry=r)
        self.sessions_created = Counter("camdirector_sessions_created", "Sessions created", registry=r)
        self.sessions_reclaimed = Counter(
            "camdirector_sessions_reclaimed", "Sessions reclaimed after the resume window or a worker loss", registry=r
        )
        self.frames = Counter("camdirector_frames", "Frames answered", ["transport"], registry=r)
        self.stale_frames = Counter("camdirector_stale_frames", "Frames answered stale (late or repeated)", registry=r)
        self.errors = Counter("camdirector_errors", "Requests answered with an error status", ["transport", "code"], registry=r)
        self.frame_compute = Histogram(
            "camdirector_frame_compute_seconds",
            "Server compute time per frame (CameraUpdate.compute_ms)",
            buckets=_SECONDS_BUCKETS,
            registry=r,
        )
        self.stage = Histogram(
            "camdirector_stage_seconds", "Time per pipeline stage per frame", ["stage"], buckets=_SECONDS_BUCKETS, registry=r
        )
        self.sessions_restored = Counter(
            "camdirector_sessions_restored",
            "Sessions rebuilt from their checkpoints (a worker or node lost, a restart)",
            registry=r,
        )
        self.checkpoint_failures = Counter(
            "camdirector_checkpoint_failures",
            "Frames answered while their session's checkpoint could not be written (the store down)",
            registry=r,
        )
        self.view_requests = Counter(
            "camdirector_view_requests", "Monitor pictures asked for, by shot (live-stream ticks included)", ["shot"], registry=r
        )
        self.view_renders = Counter(
            "camdirector_view_renders", "Monitor pictures rendered (asks answered from a shared render are not)", registry=r
        )
        self.view_streams = Gauge("camdirector_view_streams", "Live monitor streams open", registry=r)
        self.loop_lag = Histogram(
            "camdirector_loop_lag_seconds",
            "How late the front's event loop ran a timer (front/loop_watch.py)",
            buckets=_SECONDS_BUCKETS,
            registry=r,
        )
        self.request = Histogram(
            "camdirector_request_seconds",
            "Front-process time per request, routing included",
            ["transport", "rpc"],
            buckets=_SECONDS_BUCKETS,
            registry=r,
        )

    def labelled(self, metric, *values: str):
        """metric.labels(*values), kept: prometheus_client's labels() takes a lock and checks its
        arguments (about 3 us a call, seven calls a frame). Every label set here is bounded
        (transports, RPC names, status codes, stage names)."""
        key = (metric, values)
        child = self._children.get(key)
        if child is None:
            child = self._children[key] = metric.labels(*values)
        return child

    def frame_answered(
        self, transport: str, compute_ms: float, stage_ms: dict[str, float], stale: bool, checkpoint_failed: bool = False
    ) -> None:
        """One frame answered over `transport`: its compute time and stage times, ms, as the worker
        measured them (FrameMetrics)."""
        self.labelled(self.frames, transport).inc()
        if stale:
            self.stale_frames.inc()
        if checkpoint_failed:
            self.checkpoint_failures.inc()
        self.frame_compute.observe(compute_ms * 1e-3)
        for stage, ms in stage_ms.items():
            self.labelled(self.stage, stage).observe(ms * 1e-3)
