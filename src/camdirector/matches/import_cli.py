"""`camdirector import-match`: a real game's demo file written as a match file.

    camdirector import-match DEMO [--map MAP.bsp | --level NAME] --out MATCH.npz [--rate-hz 60]
                             [--data-dir DIR]
        DEMO: a QuakeWorld MVD (.mvd, or .mvd.gz) read by matches/quakeworld_mvd.py, or a
        Counter-Strike 2 demo (.dem) read by matches/cs2_demo.py: the importer is picked by the
        file's name from matches/importers.py's registry. --level NAME names the level the
        match records (default: the demo's map, "dm2"); --map MAP also adds the map to the level
        registry under its file's stem, as `camdirector level add STEM MAP` does (with the Quake
        player's height and radius as the agent's), and records that name. Writes the match
        (evaluation/match/match_file.py) and prints one JSON object: players (name, team), frames,
        duration_s, kills.
        Exit status: 0 ok, 1 the level registry is unavailable, 2 bad arguments or a demo or map
        that cannot be read.

Kept light at import, as evaluation/match/sim_cli.py: numpy and the readers load when the command runs.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from camdirector.matches.importers import IMPORTERS, importer_for, readable_suffixes


def add_parser(subparsers) -> None:
    """Registers `import-match` on an argparse subparsers object; args.handler(args) runs it."""
    p = subparsers.add_parser(
        "import-match",
        help=f"import a real game's demo ({_games()}) as a match file",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("demo", type=Path, help=f"the demo file: {readable_suffixes()}")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--map", type=Path, help="the demo's map (.bsp): added to the level registry under its stem")
    where.add_argument("--level", help="the level name to record (default: the demo's map)")
    p.add_argument("--out", type=Path, required=True, help="match file to write (.npz)")
    p.add_argument("--rate-hz", dest="rate_hz", type=float, default=60.0, help="frames per second (default 60)")
    p.add_argument("--data-dir", dest="data_dir", type=Path, help="registry folder for --map (default: per-user data dir)")
    p.set_defaults(handler=run_import_match)


def run_import_match(args: argparse.Namespace) -> int:
    """Runs `camdirector import-match` from parsed arguments; returns the exit status."""
    from camdirector.evaluation.match.match_file import save_match
    from camdirector.precompute.tracks.registry import LevelsUnavailable

    try:
        level = args.level or (_add_map(args.map, args.data_dir) if args.map else None)
        match = importer_for(args.demo).read(args.demo, level=level, rate_hz=args.rate_hz)
    except LevelsUnavailable as exc:
        print(f"camdirector import-match: {exc}", file=sys.stderr)
        return 1
    except (OSError, EOFError, ValueError) as exc:  # gzip.BadGzipFile is an OSError
        print(f"camdirector import-match: {args.demo}: {exc}", file=sys.stderr)
        return 2
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save_match(match, args.out)
    print(
        json.dumps(
            {
                "level": match.level,
                "players": [{"name": p.name, "team": p.team} for p in match.players],
                "frames": len(match.time_s),
                "duration_s": round(float(match.time_s[-1] - match.time_s[0]), 3),
                "kills": sum(e.kind == "kill" for e in match.events),
                "out": str(args.out),
            }
        )
    )
    return 0


def _games() -> str:
    """What the importers read, for the help: "QuakeWorld .mvd/.mvd.gz, CS2 .dem"."""
    return ", ".join(f"{importer.name} {'/'.join(importer.suffixes)}" for importer in IMPORTERS)


def _add_map(map_path: Path, data_dir: Path | None) -> str:
    """Adds the map to the level registry under its stem (as `camdirector level add`); its name."""
    from camdirector.geometry import quake_frame
    from camdirector.precompute.tracks.registry import LevelRegistry

    name = map_path.name.split(".")[0]
    with LevelRegistry(data_dir) as registry:
        registry.add_level(name, map_path, agent_height_m=quake_frame.PLAYER_HEIGHT_M, agent_radius_m=quake_frame.PLAYER_RADIUS_M)
    return name
