"""`camdirector play-match`: a recorded match streamed live into a server, to rehearse with the dashboard.

    camdirector play-match MATCH --server URL [--speed 1.0] [--delay-s 10] [--rate-hz 30]
                           [--director NAME] [--key-file PATH] [--ca-file CA]
                           [--session-id-file PATH] [--loop]
        opens a RIG_MATCH session for the match's players on its level (the server must hold the
        level: camdirector level add) with the broadcast delay, and streams the match over one
        gRPC StreamFrames stream in real time, --speed times as fast (matches/playback.py); with
        --loop it plays the match again and again until Ctrl-C. Prints JSON lines: first the
        session id and the players (id, name, team, team name; open it in the dashboard;
        --session-id-file writes the id there too), then one line per cut (its subjects by id
        and by name), then the summary: frames sent, answered, cuts, late frames (sent more than a
        frame period after due). Ctrl-C (SIGINT) stops sending: the server answers what was sent,
        the stream ends and the session is closed; a second Ctrl-C stops at once. The key is
        read from --key-file (a file holding it, or - for stdin), else the CAMDIRECTOR_KEY
        environment variable; --key KEY works too, but puts the key where `ps` shows it.
        Exit status: 0 played to the end, 1 the stream failed, 2 bad arguments, match file,
        server, level or key, 130 stopped by Ctrl-C.

Kept light at import, as evaluation/cli.py: numpy and the client load when the command runs.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading
from pathlib import Path


def add_parser(subparsers) -> None:
    """Registers `play-match` on an argparse subparsers object; args.handler(args) runs it."""
    p = subparsers.add_parser(
        "play-match",
        help="stream a recorded match live into a server, to rehearse with the dashboard",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("file", type=Path, metavar="MATCH", help="match file (camdirector match-sim --out)")
    p.add_argument("--server", required=True, help="the server, grpc://HOST:PORT or grpcs://HOST:PORT")
    p.add_argument("--speed", type=float, default=1.0, help="playback speed, times real time (default 1)")
    p.add_argument("--delay-s", dest="delay_s", type=float, default=10.0, help="broadcast delay, s, 0 to 300 (default 10)")
    p.add_argument(
        "--rate-hz",
        dest="rate_hz",
        type=float,
        default=30.0,
        help="frames per second sent, a divisor of the file's rate (default 30)",
    )
    p.add_argument(
        "--director",
        default="planned",
        metavar="NAME",
        help="who directs: a match director the server has (GET /v1/match-directors; default planned)",
    )
    key = p.add_mutually_exclusive_group()
    key.add_argument(
        "--key-file", dest="key_file", metavar="PATH", help="a file holding the API key (-: stdin; default: CAMDIRECTOR_KEY)"
    )
    key.add_argument("--key", help="the API key itself (visible in `ps`: prefer --key-file or CAMDIRECTOR_KEY)")
    p.add_argument("--ca-file", dest="ca_file", type=Path, help="grpcs:// only: PEM authorities to trust")
    p.add_argument("--session-id-file", dest="session_id_file", type=Path, help="write the session id here too")
    p.add_argument("--loop", action="store_true", help="play the match again and again until Ctrl-C")
    p.set_defaults(handler=run_play_match)


def _fail(message: str) -> int:
    print(f"camdirector play-match: {' '.join(str(message).split())}", file=sys.stderr)
    return 2


def _print(line: dict) -> None:
    print(json.dumps(line), flush=True)


def _refusal(server: str, error) -> str:
    """One line for a DirectorError met while opening the session."""
    name = error.code.name
    if name in ("UNAVAILABLE", "DEADLINE_EXCEEDED"):
        return f"cannot reach the server at {server}: {error}"
    if name in ("UNAUTHENTICATED", "PERMISSION_DENIED"):
        return f"the server at {server} refused the key: {error}"
    return f"the server at {server} refused the session: {error}"


def run_play_match(args: argparse.Namespace) -> int:
    """Runs `camdirector play-match` from parsed arguments; returns the exit status."""
    import camdirector_client as cd
    from camdirector.access.keys import read_key_file
    from camdirector.evaluation.match.match_file import load_match
    from camdirector.matches.playback import lap_feeds, play_match

    try:
        if not args.server.startswith(("grpc://", "grpcs://")):
            raise ValueError(f"--server {args.server!r}: give grpc://HOST:PORT or grpcs://HOST:PORT")
        if not args.speed > 0 or not args.rate_hz > 0:
            raise ValueError("--speed and --rate-hz must be positive")
        if not 0.0 <= args.delay_s <= 300.0:
            raise ValueError("--delay-s must be in [0, 300] s")
        match = load_match(args.file)
        if args.rate_hz > match.rate_hz:
            raise ValueError(f"--rate-hz {args.rate_hz:g} is above the file's {match.rate_hz:g} Hz")
        key = read_key_file(args.key_file) if args.key_file is not None else args.key
        client = cd.connect(args.server, key=key, ca_file=args.ca_file)
    except (OSError, ValueError) as exc:
        return _fail(str(exc))

    lap = next(lap_feeds(match, args.rate_hz, args.delay_s, args.loop))
    opened = []

    def on_session(session_id: str) -> None:
        opened.append(session_id)
        _print(
            {
                "session_id": session_id,
                "level": match.level,
                "players": len(match.players),
                "roster": [{"id": p.id, "name": p.name, "team": p.team, "team_name": p.team_name} for p in match.players],
                "director": args.director,
                "frames_per_lap": len(lap.rows),
                "rate_hz": round(lap.rate_hz, 2),
                "speed": args.speed,
                "delay_s": args.delay_s,
                "loop": args.loop,
            }
        )
        if args.session_id_file is not None:
            part = args.session_id_file.with_name(args.session_id_file.name + ".part")
            part.write_text(session_id + "\n")
            os.replace(part, args.session_id_file)  # a reader never sees half an id

    stop = threading.Event()

    def on_sigint(signum, frame) -> None:
        """The first Ctrl-C ends the updates (the stream then ends cleanly); a KeyboardInterrupt
        raised inside grpc's calls could leave its channel unable to close (grpc/grpc#19973),
        and `play-match --loop` once hung there for over a minute. A second one stops at once."""
        if stop.is_set():
            raise KeyboardInterrupt
        stop.set()

    signal.signal(signal.SIGINT, on_sigint)
    try:
        with client:
            result = play_match(
                client,
                match,
                director=args.director,
                delay_s=args.delay_s,
                rate_hz=args.rate_hz,
                speed=args.speed,
                loop=args.loop,
                on_session=on_session,
                on_cut=lambda line: _print({"cut": line}),
                stop=stop,
            )
    except cd.DirectorError as exc:
        if not opened:
            return _fail(_refusal(args.server, exc))
        print(f"camdirector play-match: the stream of session {opened[0]} failed: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # the session-id file could not be written
        return _fail(str(exc))
    except KeyboardInterrupt:  # before the stream began, or while closing
        print("camdirector play-match: interrupted", file=sys.stderr)
        return 130
    _print({"summary": result.summary()})
    return 130 if result.interrupted else 0
