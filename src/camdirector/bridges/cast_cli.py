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


def add_parser(subparsers) -> None:
    """Registers `cast` and its `gsi` subcommand; args.handler(args) runs it."""
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
    p.add_argument("--delay-s", dest="delay_s", type=float, default=10.0, help="broadcast delay, s, 0 to 300 (default 10)")
    p.add_argument("--rate-hz", dest="rate_hz", type=float, default=30.0, help="frames per second sent (default 30)")
    p.add_argument("--director", default="planned", metavar="NAME", help="a match director the server has (default planned)")
    p.add_argument(
        "--key-file", dest="key_file", metavar="PATH", help="a file holding the API key (-: stdin; default: CAMDIRECTOR_KEY)"
    )
    p.add_argument("--ca-file", dest="ca_file", help="grpcs:// only: PEM authorities to trust")
    p.set_defaults(handler=run_cast_gsi)


def _fail(message: str) -> int:
    print(f"camdirector cast gsi: {' '.join(str(message).split())}", file=sys.stderr)
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
        print(f"camdirector cast gsi: the stream of session {opened[0]} failed: {exc}", file=sys.stderr)
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
