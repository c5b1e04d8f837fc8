"""Prometheus metrics of the front process (served at /metrics on the HTTP address)."""

from __future__ import annotations

from bisect import bisect_left
from collections.abc import Iterator

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram
from prometheus_client.core import CounterMetricFamily, HistogramMetricFamily, Metric
from prometheus_client.registry import Collector

# 50 us .. 1 s: per-frame work is sub-millisecond when healthy.
_SECONDS_BUCKETS = (5e-5, 1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2, 2e-2, 5e-2, 0.1, 0.25, 1.0)
_BUCKET_NAMES = [*map(str, map(float, _SECONDS_BUCKETS)), "+Inf"]


class FrameFigures(Collector):
    """What the workers say of each answered frame, counted as plain numbers by the event loop's
    thread and turned into Prometheus metrics when scraped: prometheus_client's metric objects
    (a lock, a value object and a label check per update) cost about 11 us a frame for these
    six updates, this about 2. A histogram is one list, [count per bucket ..., sum], so a scrape
    (from another thread) copies each whole in one step under the GIL; its buckets are
    _SECONDS_BUCKETS, each counting the values up to and including its bound, as Prometheus's."""

    def __init__(self) -> None:
        self.frames: dict[str, int] = {}  # by transport
        self.stale = 0
        self.checkpoint_failures = 0
        self.compute = _histogram()
        self.stages: dict[str, list] = {}  # by stage name: as `compute`

    def add(self, transport: str, compute_ms: float, stage_ms: dict[str, float], stale: bool, checkpoint_failed: bool) -> None:
        self.frames[transport] = self.frames.get(transport, 0) + 1
        self.stale += stale
        self.checkpoint_failures += checkpoint_failed
        _observe(self.compute, compute_ms * 1e-3)
        stages = self.stages
        for stage, ms in stage_ms.items():
            histogram = stages.get(stage)
            if histogram is None:
                histogram = stages[stage] = _histogram()
            _observe(histogram, ms * 1e-3)

    def collect(self) -> Iterator[Metric]:
        frames = CounterMetricFamily("camdirector_frames", "Frames answered", labels=["transport"])
        for transport, count in list(self.frames.items()):
            frames.add_metric([transport], count)
        yield frames
        yield CounterMetricFamily("camdirector_stale_frames", "Frames answered stale (late or repeated)", value=self.stale)
        yield CounterMetricFamily(
            "camdirector_checkpoint_failures",
            "Frames answered while their session's checkpoint could not be written (the store down)",
            value=self.checkpoint_failures,
        )
        compute = HistogramMetricFamily(
            "camdirector_frame_compute_seconds", "Server compute time per frame (CameraUpdate.compute_ms)", labels=[]
        )
        compute.add_metric([], *_exposed(self.compute))
        yield compute
        stages = HistogramMetricFamily("camdirector_stage_seconds", "Time per pipeline stage per frame", labels=["stage"])
        for stage, histogram in list(self.stages.items()):
            stages.add_metric([stage], *_exposed(histogram))
        yield stages


def _histogram() -> list:
    """An empty histogram as FrameFigures keeps one: [count per bucket ..., sum]."""
    return [0] * len(_BUCKET_NAMES) + [0.0]


def _observe(histogram: list, value_s: float) -> None:
    histogram[bisect_left(_SECONDS_BUCKETS, value_s)] += 1
    histogram[-1] += value_s


def _exposed(histogram: list) -> tuple[list[tuple[str, float]], float]:
    """(cumulative buckets, sum) of a histogram list, copied first (FrameFigures)."""
    copy = histogram[:]
    cumulative, total = [], 0
    for name, count in zip(_BUCKET_NAMES, copy):
        total += count
        cumulative.append((name, total))
    return cumulative, copy[-1]


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
        self.frame_figures = FrameFigures()
        r.register(self.frame_figures)
        self.edge_frames = Counter(
            "camdirector_edge_frames",
            "Frames the compiled gRPC edge answered with no Python in the front (grpc_front compiled)",
            registry=r,
        )
        self.errors = Counter("camdirector_errors", "Requests answered with an error status", ["transport", "code"], registry=r)
        self.sessions_restored = Counter(
            "camdirector_sessions_restored",
            "Sessions rebuilt from their checkpoints (a worker or node lost, a restart)",
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
        self.frame_figures.add(transport, compute_ms, stage_ms, stale, checkpoint_failed)
