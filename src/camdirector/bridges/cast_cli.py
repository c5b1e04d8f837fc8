"""`camdirector cast`: a live game's own feed directing a RIG_MATCH session.

    camdirector cast gsi --listen 127.0.0.1:3000 --token T --level NAME --server URL
                         [--netcon 127.0.0.1:2121] [--netcon-rate-hz 10] [--delay-s 10]
                         [--rate-hz 30] [--director NAME] [--key-file PATH] [--ca-file CA]
        listens for Counter-Strike 2's Game State Integration payloads (bridges/gsi_server.py),
        opens a RIG_MATCH session for their players on the level once the first comes, and sends
        a frame every 1 / rate_hz s with the players interpolated between payloads
        (bridges/gsi_cast.py); with --netcon, the program's camera goes to the game's console as
        spec_goto lines (bridges/netcon.py). Prints JSON lines: the session and its players, then
        one progress line a second (payloads, frames, kills, the program's shot), then the
        summary. Ctrl-C stops. Exit status: 0 stopped by Ctrl-C after a session ran, 1 the
        stream failed, 2 bad arguments, server, level or key.
    camdirector cast gsi --print-config [--listen ...] --token T
        prints the gamestate_integration_camdirector.cfg to put in the game's cfg folder.

    camdirector cast qtv qtv://HOST:PORT[/STREAM] (--level NAME | --map MAP.bsp) --server URL
                         [--delay-s 10] [--rate-hz 30] [--director NAME] [--key-file PATH]
                         [--ca-file CA] [--data-dir DIR] [--program-out FILE.jsonl]
                         [--password PASSWORD]
        connects to a QuakeWorld QTV source (mvdsv, or a QTV proxy's STREAM) as a QTV client,
        decodes the live MVD stream as it comes and drives a RIG_MATCH session on the level
        (bridges/qtv.py): players interpolated at rate_hz, frags as kill events, their stats;
        reconnects with backoff when the source drops or sends a bad stream (one error line on
        stderr each time), in the same session. A player who joins (or takes a slot) later ends
        the session and opens the next with every player (one warning line; the program starts
        again after the delay). --map MAP.bsp adds the map to the level registry first, under its
        stem, as import-match --map does. Prints JSON lines: each session and its players, one
        progress line a second (players, frags, the program's shot, connections), then the
        summary. --password answers a source that asks for one
        (mvdsv's qtv_password; MD4, CCITT or PLAIN as ezQuake does, bridges/qtv_auth.py); a
        wrong one is a refusal. --program-out writes the program received as it comes,
        one JSON line a program moment with the demo time it shows (bridges/program_record.py),
        for `camdirector eval-match MATCH --program FILE` (a later session's in FILE's stem.1.jsonl,
        .2, ...). Ctrl-C stops. Exit status: 0 stopped
        by Ctrl-C after a session ran, 1 the stream to the server failed or the level registry
        is unavailable, 2 bad arguments, map, server, key, a --program-out that cannot be
        written, or a QTV source that refused the stream or could not be reached.

Kept light at import, as play_cli.py: the client loads when the command runs. `cast` has
subcommands so that other feeds join it.
"""

from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
import threading
from pathlib import Path


def add_parser(subparsers) -> None:
    """Registers `cast` and its `gsi` and `qtv` subcommands; args.handler(args) runs them."""
    cast = subparsers.add_parser("cast", help="direct a live game from its own feed", description=__doc__.split("\n\n")[0])
    feeds = cast.add_subparsers(dest="feed", required=True)
    p = feeds.add_parser(
        "gsi",
        help="Counter-Strike 2 over Game State Integration",
        description=__doc__.split("\n\n")[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--listen", default="127.0.0.1:3000", metavar="HOST:PORT", help="where the game posts (default 127.0.0.1:3000)"
    )
    p.add_argument("--token", required=True, help="the auth token of the cfg; payloads without it are refused (401)")
    p.add_argument("--print-config", dest="print_config", action="store_true", help="print the game's cfg and exit")
    p.add_argument("--level", help="the level the session runs on (camdirector level add)")
    p.add_argument("--server", help="the server, grpc://HOST:PORT or grpcs://HOST:PORT")
    p.add_argument("--netcon", metavar="HOST:PORT", help="the game's console (-netconport): send it the program as spec_goto")
    p.add_argument("--netcon-rate-hz", dest="netcon_rate_hz", type=float, default=10.0, help="most spec_goto lines a second (10)")
    _add_session_args(p)
    p.set_defaults(handler=run_cast_gsi)

    q = feeds.add_parser(
        "qtv",
        help="QuakeWorld over QTV (mvdsv or a QTV proxy)",
        description=__doc__.split("\n\n")[2],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    q.add_argument("url", metavar="qtv://HOST:PORT[/STREAM]", help="the QTV source (port default 27500)")
    where = q.add_mutually_exclusive_group(required=True)
    where.add_argument("--level", help="the level the session runs on (camdirector level add)")
    where.add_argument("--map", type=Path, help="the match's map (.bsp): added to the level registry under its stem first")
    q.add_argument("--data-dir", dest="data_dir", type=Path, help="registry folder for --map (default: per-user data dir)")
    q.add_argument("--server", required=True, help="the server, grpc://HOST:PORT or grpcs://HOST:PORT")
    q.add_argument("--password", default="", help="the source's qtv_password, if it asks for one")
    q.add_argument(
        "--program-out",
        dest="program_out",
        type=Path,
        metavar="FILE.jsonl",
        help="write the program received here, for eval-match --program",
    )
    _add_session_args(q)
    q.set_defaults(handler=run_cast_qtv)


def _add_session_args(p: argparse.ArgumentParser) -> None:
    """The RIG_MATCH session's flags every feed takes: delay, rate, director, key and CA."""
    p.add_argument("--delay-s", dest="delay_s", type=float, default=10.0, help="broadcast delay, s, 0 to 300 (default 10)")
    p.add_argument("--rate-hz", dest="rate_hz", type=float, default=30.0, help="frames per second sent (default 30)")
    p.add_argument("--director", default="planned", metavar="NAME", help="a match director the server has (default planned)")
    p.add_argument(
        "--key-file", dest="key_file", metavar="PATH", help="a file holding the API key (-: stdin; default: CAMDIRECTOR_KEY)"
    )
    p.add_argument("--ca-file", dest="ca_file", help="grpcs:// only: PEM authorities to trust")


def _fail(message: str, feed: str = "gsi") -> int:
    print(f"camdirector cast {feed}: {' '.join(str(message).split())}", file=sys.stderr)
    return 2


def _print(line: dict) -> None:
    print(json.dumps(line), flush=True)


def _address(text: str, flag: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    if not host or not port.isdigit():
        raise ValueError(f"{flag} {text!r}: give HOST:PORT")
    return host, int(port)


def run_cast_gsi(args: argparse.Namespace) -> int:
    """Runs `camdirector cast gsi` from parsed arguments; returns the exit status."""
    from camdirector.bridges.gsi_server import gamestate_config
    from camdirector.bridges.gsi_settings import GsiDriverSettings, GsiEndpointSettings, NetconSettings

    try:
        host, port = _address(args.listen, "--listen")
        endpoint = GsiEndpointSettings(host=host, port=port, token=args.token)
        if args.print_config:
            print(gamestate_config(endpoint), end="")
            return 0
        if not args.level or not args.server:
            raise ValueError("--level and --server are required (unless --print-config)")
        if not args.server.startswith(("grpc://", "grpcs://")):
            raise ValueError(f"--server {args.server!r}: give grpc://HOST:PORT or grpcs://HOST:PORT")
        driver = GsiDriverSettings(rate_hz=args.rate_hz, delay_s=args.delay_s)
        netcon = None
        if args.netcon:
            n_host, n_port = _address(args.netcon, "--netcon")
            netcon = NetconSettings(host=n_host, port=n_port, rate_hz=args.netcon_rate_hz)
    except ValueError as exc:
        return _fail(str(exc))
    return _run(args, endpoint, driver, netcon)


def _run(args: argparse.Namespace, endpoint_settings, driver, netcon_settings) -> int:
    import camdirector_client as cd
    from camdirector.access.keys import read_key_file
    from camdirector.bridges.gsi_cast import cast_gsi
    from camdirector.bridges.gsi_server import GsiEndpoint
    from camdirector.bridges.gsi_tracks import GsiTracks
    from camdirector.bridges.netcon import NetconSender

    logging.basicConfig(level=logging.WARNING, format="camdirector cast gsi: %(message)s", stream=sys.stderr)
    tracks = GsiTracks(interp_delay_s=driver.interp_delay_s, hold_s=driver.hold_s)
    netcon = None if netcon_settings is None else NetconSender(netcon_settings)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda signum, frame: stop.set())
    signal.signal(signal.SIGTERM, lambda signum, frame: stop.set())
    try:
        key = read_key_file(args.key_file) if args.key_file is not None else None
        client = cd.connect(args.server, key=key, ca_file=args.ca_file)
        endpoint = GsiEndpoint(endpoint_settings, tracks)
    except (OSError, ValueError) as exc:
        return _fail(str(exc))
    _print({"listening": f"{endpoint_settings.host}:{endpoint.port}", "level": args.level, "director": args.director})

    opened: list[str] = []

    def on_session(session_id: str) -> None:
        opened.append(session_id)
        roster = [{"id": p.id, "name": p.name, "team": p.team, "team_name": p.team_name} for p in tracks.roster]
        _print({"session_id": session_id, "players": len(roster), "roster": roster, "rate_hz": driver.rate_hz})

    def on_progress(c) -> None:
        _print(
            {
                "payloads": tracks.counts.accepted,
                "refused": endpoint.refused,
                "players": len(tracks.roster),
                "frames": c.frames,
                "kills": c.kills,
                "stale_ticks": c.stale,
                "shot": c.last_shot,
                "spec_goto": None if netcon is None else netcon.sent,
            }
        )

    try:
        with client, endpoint:
            counts = cast_gsi(
                client,
                tracks,
                driver,
                level=args.level,
                director=args.director,
                stop=stop,
                netcon=netcon,
                on_session=on_session,
                on_progress=on_progress,
            )
    except cd.DirectorError as exc:
        if not opened:
            return _fail(f"the server at {args.server} refused the session: {exc}")
        print(f"camdirector cast gsi: the stream of session {opened[-1]} failed: {exc}", file=sys.stderr)
        return 1
    finally:
        if netcon is not None:
            netcon.close()
    c = tracks.counts
    _print(
        {
            "summary": {
                "payloads": c.accepted,
                "duplicates": c.duplicate,
                "out_of_order": c.out_of_order,
                "refused": endpoint.refused,
                "sessions": counts.sessions,
                "frames": counts.frames,
                "answered": counts.answered,
                "program_frames": counts.program,
                "cuts": counts.cuts,
                "kills": counts.kills,
                "spec_goto": None if netcon is None else netcon.sent,
            }
        }
    )
    return 0


def run_cast_qtv(args: argparse.Namespace) -> int:
    """Runs `camdirector cast qtv` from parsed arguments; returns the exit status."""
    from camdirector.bridges.qtv import QtvSettings, parse_qtv_url

    try:
        parse_qtv_url(args.url)
        if not args.server.startswith(("grpc://", "grpcs://")):
            raise ValueError(f"--server {args.server!r}: give grpc://HOST:PORT or grpcs://HOST:PORT")
        settings = QtvSettings(rate_hz=args.rate_hz, delay_s=args.delay_s, password=args.password)
    except ValueError as exc:
        return _fail(str(exc), "qtv")
    level = args.level
    if args.map is not None:
        from camdirector.matches.import_cli import add_map, map_level_name
        from camdirector.precompute.tracks.registry import LevelsUnavailable

        level = map_level_name(args.map)
        try:
            add_map(args.map, level, args.data_dir)
        except LevelsUnavailable as exc:
            print(f"camdirector cast qtv: {exc}", file=sys.stderr)
            return 1
        except (OSError, ValueError) as exc:
            return _fail(f"{args.map}: {exc}", "qtv")
    return _run_qtv(args, settings, level)


def _run_qtv(args: argparse.Namespace, settings, level: str) -> int:
    import camdirector_client as cd
    from camdirector.access.keys import read_key_file
    from camdirector.bridges.qtv import QtvError, cast_qtv

    logging.basicConfig(level=logging.WARNING, format="camdirector cast qtv: %(message)s", stream=sys.stderr)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda signum, frame: stop.set())
    signal.signal(signal.SIGTERM, lambda signum, frame: stop.set())
    try:
        key = read_key_file(args.key_file) if args.key_file is not None else None
        client = cd.connect(args.server, key=key, ca_file=args.ca_file)
    except (OSError, ValueError) as exc:
        return _fail(str(exc), "qtv")
    _print({"source": args.url, "level": level, "director": args.director, "delay_s": settings.delay_s})
    opened: list[str] = []

    def on_session(session_id: str, roster) -> None:
        opened.append(session_id)
        players = [{"id": p.id, "name": p.name, "team": p.team, "team_name": p.team_name} for p in roster]
        _print({"session_id": session_id, "players": len(players), "roster": players, "rate_hz": settings.rate_hz})

    def on_progress(c, receiver, tracks) -> None:
        _print(
            {
                "players": len(tracks.roster),
                "frags": len(tracks.kills),
                "shot": c.last_shot,
                "frames": c.frames,
                "stale_ticks": c.stale,
                "connections": receiver.connections,
            }
        )

    try:
        with client:
            done = cast_qtv(
                client,
                args.url,
                settings,
                level=level,
                director=args.director,
                stop=stop,
                on_session=on_session,
                on_progress=on_progress,
                program_out=args.program_out,
            )
    except QtvError as exc:
        return _fail(str(exc), "qtv")
    except OSError as exc:  # --program-out cannot be written
        return _fail(f"--program-out: {exc}", "qtv")
    except cd.DirectorError as exc:
        if not opened:
            return _fail(f"the server at {args.server} refused the session: {exc}", "qtv")
        print(f"camdirector cast qtv: the stream of session {opened[-1]} failed: {exc}", file=sys.stderr)
        return 1
    c, r = done.session, done.receiver
    _print(
        {
            "summary": {
                "sessions": c.sessions,
                "frames": c.frames,
                "answered": c.answered,
                "program_frames": c.program,
                "cuts": c.cuts,
                "kills": c.kills,
                "connections": r.connections,
                "drops": r.drops,
                "bad_streams": r.bad_streams,
                "bytes": r.bytes,
                "program_out": None if args.program_out is None else str(args.program_out),
            }
        }
    )
    return 0
