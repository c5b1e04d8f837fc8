"""The GSI bridge's own cost, per payload and per frame, against play-match's per frame on the same
players (issue 42: the bridges' per-frame overhead measured against play-match of the same match).

    python -m load_tests.gsi_bridge [--json FILE] [--frames N]

The players are the ten of the recorded payload (tests/data/gsi). Measured in this process, no
server (what is measured is the bridge's side of the wire):
- payload_us: one payload taken in: parse_payload of its body (JSON, ~12 KB) and GsiTracks.offer.
- bridge_frame_us: one frame out of the bridge: GsiTracks.sample (interpolated positions) and
  live_session.frame_update, serialized (the bytes a StreamFrames message carries).
- play_match_frame_us: one frame out of play-match for the same ten players at the same positions:
  session_feed.frame_updates over a match file of them, serialized.
- floor_frame_us: the least any frame costs: the same ten packed transforms alone (pack_states,
  frame_update, serialized), from the same run.
Medians over N repetitions, microseconds; ratios to the floor. Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import camdirector_client as cd
from camdirector.bridges.gsi import parse_payload
from camdirector.bridges.gsi_tracks import GsiTracks
from camdirector.bridges.live_session import frame_update
from camdirector.evaluation.match.match_file import MatchRecording
from camdirector.evaluation.match.session_feed import Feed, frame_updates
from camdirector.matches.cs2_demo import view_rotation

PAYLOAD = Path(__file__).resolve().parents[1] / "tests" / "data" / "gsi" / "csgo_gsi_radar_de_mirage_round9.json"


class _Session:
    """What frame_update needs of a session: its frame_update, without a server."""

    id = "bench"

    def frame_update(self, frame: int, time_s: float, **kw) -> cd.pb.FrameUpdate:
        return cd.wire.frame_update(self.id, frame, time_s, **kw)


def _median_us(call, n: int) -> float:
    times = np.empty(n)
    for i in range(n):
        t = time.perf_counter()
        call(i)
        times[i] = time.perf_counter() - t
    return float(np.median(times) * 1e6)


def run(frames: int) -> dict:
    raw = json.loads(PAYLOAD.read_text())
    bodies = [json.dumps({**raw, "provider": {**raw["provider"], "timestamp": 1 + i}}).encode() for i in range(frames)]
    tracks = GsiTracks(interp_delay_s=0.1, hold_s=2.0)
    session = _Session()
    payload_us = _median_us(lambda i: tracks.offer(parse_payload(bodies[i]), str(i).encode(), float(i)), frames)
    bridge_us = _median_us(
        lambda i: frame_update(session, i + 1, i / 30.0, tracks.sample(frames + i / 30.0)).SerializeToString(), frames
    )

    sample = tracks.sample(float(frames))
    n = len(sample.ids)
    rotations = view_rotation(np.zeros(n), sample.yaw_deg)
    match = MatchRecording(
        level="bench",
        seed=0,
        rate_hz=30.0,
        players=tracks.roster,
        time_s=np.arange(frames) / 30.0,
        positions_world=np.repeat(sample.positions_world[None], frames, axis=0),
        rotations_xyzw=np.repeat(rotations[None], frames, axis=0),
        alive=np.ones((frames, n), dtype=bool),
        events=[],
        stats=np.zeros((frames, n, 4), dtype=np.int32),
    )
    updates = frame_updates(session, match, Feed.of(match, 30.0, 0.0), list(range(n)), events=True)
    play_us = _median_us(lambda i: next(updates).SerializeToString(), frames)
    floor_us = _median_us(
        lambda i: session.frame_update(
            i + 1, i / 30.0, packed=cd.pack_states(sample.ids, sample.positions_world, rotations)
        ).SerializeToString(),
        frames,
    )
    return {
        "players": n,
        "frames": frames,
        "payload_bytes": len(bodies[0]),
        "payload_us": round(payload_us, 1),
        "bridge_frame_us": round(bridge_us, 1),
        "play_match_frame_us": round(play_us, 1),
        "floor_frame_us": round(floor_us, 1),
        "bridge_over_floor": round(bridge_us / floor_us, 2),
        "play_match_over_floor": round(play_us / floor_us, 2),
        "bridge_over_play_match": round(bridge_us / play_us, 2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--json", type=Path, help="also write the result here")
    args = parser.parse_args()
    result = run(args.frames)
    print(json.dumps(result))
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
