"""The QTV bridge's own cost per frame, and its round trip into a real server, against play-match's
on the same match (issue 42: the bridges' per-frame overhead measured against play-match of the
same match).

    python -m load_tests.qtv_bridge [--json FILE] [--seconds 28] [--reps 3]

The match: the first `seconds` of the 2on2 frobodm2 development demo (tests/data/real_matches),
sent at 30 frames a second. The bridge's frames come from the demo's bytes as a QTV stream brings
them (1460-byte segments, a TCP segment's payload), decoded by mvd_wire.MvdStream into
qtv.QtvTracks on the demo's own clock (the stream arriving in real time) and sampled interp_delay_s (0.15 s) behind
at each frame; play-match's from the match file import-match makes of the same demo at 30 Hz
(session_feed.frame_updates, as play-match sends them). Measured:
- in this process, no server, medians, means and p99 over `reps` passes over the frames, microseconds:
  bridge_frame_us, one bridge frame: the segments up to its time decoded and offered
  (decode_offer_us), then QtvTracks.sample (interpolation) and live_session.frame_update,
  serialized (sample_build_us); play_match_frame_us, one play-match frame serialized; floor_frame_us,
  the least a frame costs: the same players' packed transforms alone (pack_states, frame_update,
  serialized).
- end to end, one `camdirector serve` with the map's level: each frame built and sent with
  Session.send (one Frame request, its camera back; build included) through a RIG_MATCH session of the
  planned director (the same targets for both: the demo's players), bridge and play-match in turn,
  milliseconds; the floor a gRPC health check against the same server in the same run.
Ratios to the floor and of the bridge to play-match. Prints one JSON object.
"""

from __future__ import annotations

import argparse
import gzip
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import grpc
import numpy as np
from grpc_health.v1 import health_pb2, health_pb2_grpc

import camdirector_client as cd
from camdirector.bridges.live_session import frame_update
from camdirector.bridges.qtv import QtvSettings, QtvTracks
from camdirector.deploy.server_process import ServerProcess
from camdirector.evaluation.match.match_file import MatchRecording
from camdirector.evaluation.match.session_feed import Feed, frame_updates, match_session_fields
from camdirector.matches.import_cli import add_map
from camdirector.matches.mvd_wire import MvdStream
from camdirector.matches.quakeworld_mvd import import_mvd
from load_tests.report import emit, summary

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
DEMO = DATA / "real_matches" / "2on2_sf_vs_red_frobodm2_220104-0915.mvd.gz"
MAP = DATA / "real_maps" / "frobodm2.bsp.gz"
SEGMENT_BYTES = 1460  # a TCP segment's payload: how a stream's bytes arrive
RATE_HZ = 30.0
DELAY_S = 2.0  # the sessions' broadcast delay, s


class _Session:
    """What frame_update needs of a session: its frame_update, without a server."""

    id = "bench"

    def frame_update(self, frame: int, time_s: float, **kw) -> cd.pb.FrameUpdate:
        return cd.wire.frame_update(self.id, frame, time_s, **kw)


class BridgeFrames:
    """The bridge's side of a cast over the demo's bytes: frame(k) decodes the segments up to
    frame k's time, samples the tracks there and builds the frame (module docstring)."""

    def __init__(self, demo: bytes, times_s: np.ndarray, session):
        self.segments = [demo[i : i + SEGMENT_BYTES] for i in range(0, len(demo), SEGMENT_BYTES)]
        self.times_s, self.session = times_s, session
        settings = QtvSettings()
        self.tracks = QtvTracks(settings.interp_delay_s, settings.hold_s)
        self.stream = MvdStream()
        self.next_segment = 0
        self.demo_time_s = -np.inf

    def decode_until(self, t: float) -> None:
        """Feeds segments until the decoded stream reaches demo time t (or ends)."""
        while self.demo_time_s < t and self.next_segment < len(self.segments):
            update = self.stream.feed(self.segments[self.next_segment])
            self.next_segment += 1
            self.demo_time_s = update.time_s
            self.tracks.offer(update, update.time_s)

    def build(self, k: int) -> cd.pb.FrameUpdate:
        t = float(self.times_s[k])
        return frame_update(self.session, k + 1, t, self.tracks.sample(t))

    def frame(self, k: int) -> cd.pb.FrameUpdate:
        self.decode_until(float(self.times_s[k]))
        return self.build(k)


def _timed(call: Callable[[int], object], n: int) -> np.ndarray:
    """(n,) seconds of call(0), call(1), ..."""
    times = np.empty(n)
    for i in range(n):
        t = time.perf_counter()
        call(i)
        times[i] = time.perf_counter() - t
    return times


def in_process(demo: bytes, match: MatchRecording, reps: int) -> dict:
    """The per-frame costs without a server (module docstring), over `reps` passes."""
    session = _Session()
    feed = Feed.of(match, RATE_HZ, 0.0)
    n = len(feed.rows)
    ids = [p.id for p in match.players]
    times = {"decode_offer": [], "sample_build": [], "bridge": [], "play_match": [], "floor": []}
    for _ in range(reps):
        bridge = BridgeFrames(demo, feed.times_s, session)
        decode, build = np.empty(n), np.empty(n)
        for k in range(n):
            t0 = time.perf_counter()
            bridge.decode_until(float(feed.times_s[k]))
            t1 = time.perf_counter()
            bridge.build(k).SerializeToString()
            decode[k], build[k] = t1 - t0, time.perf_counter() - t1
        times["decode_offer"].append(decode)
        times["sample_build"].append(build)
        times["bridge"].append(decode + build)
        updates = frame_updates(session, match, feed, list(range(len(match.players))), events=True)
        times["play_match"].append(_timed(lambda k, updates=updates: next(updates).SerializeToString(), n))
        times["floor"].append(
            _timed(
                lambda k: session.frame_update(
                    k + 1,
                    float(feed.times_s[k]),
                    packed=cd.pack_states(ids, match.positions_world[feed.rows[k]], match.rotations_xyzw[feed.rows[k]]),
                ).SerializeToString(),
                n,
            )
        )
    us = {name: summary(np.concatenate(v), 1e6) for name, v in times.items()}
    # a segment brings a few frames' blocks at once: most frames decode nothing, so the mean says
    # what decoding costs a frame, the median does not
    for name, v in times.items():
        us[name]["mean"] = round(float(np.mean(np.concatenate(v))) * 1e6, 3)
    return {
        "frames": n,
        "bridge_frame_us": us["bridge"],
        "decode_offer_us": us["decode_offer"],
        "sample_build_us": us["sample_build"],
        "play_match_frame_us": us["play_match"],
        "floor_frame_us": us["floor"],
        "bridge_over_floor": round(us["bridge"]["median"] / us["floor"]["median"], 2),
        "play_match_over_floor": round(us["play_match"]["median"] / us["floor"]["median"], 2),
        "bridge_over_play_match": round(us["bridge"]["median"] / us["play_match"]["median"], 2),
    }


def end_to_end(demo: bytes, match: MatchRecording, data_dir: Path) -> dict:
    """The round trips through one server (module docstring), ms."""
    with (
        ServerProcess("--workers", "1", "--data-dir", str(data_dir), transports=("grpc",)) as server,
        cd.connect(server.url("grpc"), timeout_s=60.0) as client,
        grpc.insecure_channel(server.grpc) as channel,
    ):
        health = health_pb2_grpc.HealthStub(channel)
        feed = Feed.of(match, RATE_HZ, 0.0)
        n = len(feed.rows)
        fields = match_session_fields(match, "planned", DELAY_S, 0)
        with client.create_session(**fields) as session:
            bridge = BridgeFrames(demo, feed.times_s, session)
            bridge_s = _timed(lambda k: session.send(bridge.frame(k)), n)
        with client.create_session(**fields) as session:
            updates = frame_updates(session, match, feed, list(range(len(match.players))), events=True)
            play_s = _timed(lambda k: session.send(next(updates)), n)
        floor_s = _timed(lambda k: health.Check(health_pb2.HealthCheckRequest()), n)
    ms = {"bridge": summary(bridge_s, 1e3), "play_match": summary(play_s, 1e3), "floor": summary(floor_s, 1e3)}
    return {
        "director": "planned",
        "delay_s": DELAY_S,
        "bridge_rtt_ms": ms["bridge"],
        "play_match_rtt_ms": ms["play_match"],
        "floor_rtt_ms": ms["floor"],
        "bridge_over_play_match": round(ms["bridge"]["median"] / ms["play_match"]["median"], 3),
        "bridge_over_play_match_p99": round(ms["bridge"]["p99"] / ms["play_match"]["p99"], 3),
        "bridge_minus_play_match_ms": round(ms["bridge"]["median"] - ms["play_match"]["median"], 3),
    }


def map_data_dir(folder: Path) -> Path:
    """folder / "data": a data folder holding the demo's map as frobodm2, added as `cast qtv --map` adds it."""
    bsp = folder / "frobodm2.bsp"
    bsp.write_bytes(gzip.decompress(MAP.read_bytes()))
    add_map(bsp, "frobodm2", folder / "data")
    return folder / "data"


def run(seconds: float, reps: int, server: bool) -> dict:
    raw = gzip.decompress(DEMO.read_bytes())
    full = import_mvd(raw, level="frobodm2", rate_hz=RATE_HZ)
    match = full.until(full.time_s[0] + seconds)
    result = {
        "demo": DEMO.name,
        "seconds": seconds,
        "players": len(match.players),
        "rate_hz": RATE_HZ,
        "in_process": in_process(raw, match, reps),
    }
    if server:
        with tempfile.TemporaryDirectory() as folder:
            result["end_to_end"] = end_to_end(raw, match, map_data_dir(Path(folder)))
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=28.0, help="the demo's first seconds (default 28)")
    parser.add_argument("--reps", type=int, default=3, help="passes over the frames in process (default 3)")
    parser.add_argument("--no-server", dest="server", action="store_false", help="skip the end-to-end round trips")
    parser.add_argument("--json", type=Path, help="also write the result here")
    args = parser.parse_args(argv)
    emit(run(args.seconds, args.reps, args.server), args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
