"""Whether the same match streamed over gRPC gives the same program (issue 41): a real match, its
map added anew as a level in a fresh data folder, played into a fresh `camdirector serve` by our
own client (the SDK's stream, play-match's pacing), paced in real time at the rate and unpaced (as
fast as the server answers); twice, into two servers. Every reply after the delay filled is kept
(the program frame, the pose's position, rotation and field of view, the cut, the shot, whether it
came stale) and compared float for float: between the two servers (their string hashes seeded
apart), and paced against unpaced.

    python -m load_tests.same_program [--match 2on2_frobodm2] [--seconds 40] [--directors planned,hltv,autotrack]
                                      [--rate-hz 30] [--delay 10] [--frame-timeout 3] [--json FILE]

Per director and pacing: the replies, the stale ones (a frame sent again after the client's
stream was cut, answered with its first answer), how many differ and by how far (m), the cuts.
The streams of one pacing run at once, every director in both servers. tests/load_tests/
test_same_program.py runs a short slice of it in `make test`.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from load_tests.real_matches import MATCHES, prepare
from load_tests.report import emit

PACINGS = {"paced": 1.0, "unpaced": 1e6}  # the playback's speeds: real time, and as fast as the server answers
# streamed_program's columns
FRAME, POSITION, ROTATION, FOV, CUT, SHOT, STALE = 0, slice(1, 4), slice(4, 8), 8, 9, 10, 11


def streamed_program(
    url: str, match, director: str, delay_s: float, rate_hz: float, speed: float, frame_timeout_s: float | None
) -> np.ndarray:
    """The replies of the server at `url` to the match played at `speed` (1: paced in real time,
    huge: unpaced), buffering ones left out: (m, 12) rows of program frame, position (3) m,
    rotation xyzw (4), vertical fov deg, cut, shot id, stale. frame_timeout_s: the client's
    hung-node watchdog (camdirector_client.RetryPolicy)."""
    import camdirector_client as cd
    from camdirector.evaluation.match.session_feed import match_session_fields
    from camdirector.matches.playback import PlaybackCounts, lap_feeds, paced_updates

    rows = []
    fields, retry = match_session_fields(match, director, delay_s, 0), cd.RetryPolicy(frame_timeout_s=frame_timeout_s)
    with cd.connect(url, retry=retry) as client, client.create_session(**fields) as session:
        feeds = lap_feeds(match, rate_hz, delay_s, loop=False)
        updates = paced_updates(session, match, feeds, speed, time.monotonic, threading.Event(), PlaybackCounts())
        for u in session.stream(updates):
            if u.buffering:
                continue
            p, q = u.pose.position, u.pose.rotation
            rows.append((u.frame, p.x, p.y, p.z, q.x, q.y, q.z, q.w, u.pose.vertical_fov_deg, u.cut, u.shot_id, u.stale))
    return np.array(rows, dtype=np.float64).reshape(-1, 12)


def compare(a: np.ndarray, b: np.ndarray) -> dict:
    """How two programs (streamed_program's rows) differ: replies and stale ones, rows not equal
    in every float (matched by order, as a client sees them) and how far apart their cameras are
    (m), the first such frame, and the cuts of each."""
    out: dict = {
        "replies": [len(a), len(b)],
        "stale": [int(a[:, STALE].sum()), int(b[:, STALE].sum())],
        "cuts": [int(a[:, CUT].sum()), int(b[:, CUT].sum())],
    }
    n = min(len(a), len(b))
    differs = np.any(a[:n] != b[:n], axis=1)
    out["rows_differing"] = int(differs.sum()) + abs(len(a) - len(b))
    out["max_distance_m"] = round(float(np.linalg.norm(a[:n, POSITION] - b[:n, POSITION], axis=1).max(initial=0.0)), 3)
    out["first_difference_frame"] = int(a[np.argmax(differs), FRAME]) if differs.any() else None
    out["same"] = out["rows_differing"] == 0
    return out


@contextlib.contextmanager
def fresh_server(match_name: str, seconds: float, folder: Path, hash_seed: int) -> Iterator[tuple[object, str]]:
    """The match (its first `seconds`) with its map added as a level in a new data folder under
    `folder`, and a new `camdirector serve` (gRPC only) on it whose string hashes are seeded with
    hash_seed (PYTHONHASHSEED: two servers given two seeds iterate sets of names in two orders):
    yields (match, gRPC URL)."""
    from camdirector.deploy.server_process import ServerProcess

    folder.mkdir(parents=True, exist_ok=True)
    match = prepare(match_name, folder, seconds / 60.0)
    with ServerProcess(
        "--data-dir", str(folder / "data"), transports=("grpc",), env={"PYTHONHASHSEED": str(hash_seed)}
    ) as server:
        url = server.url("grpc")
        assert url is not None  # started with gRPC
        yield match, url


def programs_twice(
    match_name: str,
    seconds: float,
    directors: list[str],
    delay_s: float,
    rate_hz: float,
    frame_timeout_s: float | None,
    folder: Path,
) -> dict[tuple[str, str], list[np.ndarray]]:
    """Per (director, pacing), the programs of two fresh servers (fresh_server, in folder/0 and
    folder/1, hash seeds 1 and 2). Each pacing's streams run at once."""
    out: dict[tuple[str, str], list[np.ndarray]] = {}
    with contextlib.ExitStack() as stack:
        served = [stack.enter_context(fresh_server(match_name, seconds, folder / str(i), i + 1)) for i in range(2)]
        for pacing, speed in PACINGS.items():
            with ThreadPoolExecutor(max_workers=2 * len(directors)) as pool:
                runs = {
                    (director, i): pool.submit(streamed_program, url, match, director, delay_s, rate_hz, speed, frame_timeout_s)
                    for director in directors
                    for i, (match, url) in enumerate(served)
                }
                for director in directors:
                    out[(director, pacing)] = [runs[(director, i)].result() for i in range(2)]
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--match", default="2on2_frobodm2", choices=sorted(MATCHES))
    parser.add_argument("--seconds", type=float, default=40.0, help="the match's first seconds played (default 40)")
    parser.add_argument("--directors", default="planned,hltv,autotrack", help="comma-separated directors")
    parser.add_argument("--rate-hz", dest="rate_hz", type=float, default=30.0, help="frames a second sent (default 30)")
    parser.add_argument("--delay", type=float, default=10.0, help="broadcast delay, s (default 10)")
    parser.add_argument("--frame-timeout", dest="frame_timeout_s", type=float, default=3.0, help="the client's, s (default 3)")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    directors = args.directors.split(",")
    with tempfile.TemporaryDirectory(prefix="same-program-") as tmp:
        runs = programs_twice(args.match, args.seconds, directors, args.delay, args.rate_hz, args.frame_timeout_s, Path(tmp))
    result: dict = {"benchmark": "same_program", "match": args.match, "seconds": args.seconds, "delay_s": args.delay}
    for director in directors:
        paced, unpaced = runs[(director, "paced")], runs[(director, "unpaced")]
        result[director] = {
            "paced_twice": compare(*paced),
            "unpaced_twice": compare(*unpaced),
            "paced_vs_unpaced": compare(paced[0], unpaced[0]),
        }
    emit(result, args.json)
    return 0 if all(c["same"] for d in directors for c in result[d].values()) else 1


if __name__ == "__main__":
    sys.exit(main())
