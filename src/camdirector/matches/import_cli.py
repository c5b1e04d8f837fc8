"""`camdirector import-match`: a real game's demo file written as a match file.

    camdirector import-match DEMO [--map MAP.bsp | --level NAME] --out MATCH.npz [--rate-hz 60]
                             [--data-dir DIR]
        DEMO: a QuakeWorld MVD (.mvd, or .mvd.gz) read by matches/quakeworld_mvd.py, or a
        Counter-Strike 2 demo (.dem) read by matches/cs2_demo.py: the importer is picked by the
        file's name from matches/importers.py's registry. --level NAME names the level the
        match records (default: the demo's map, "dm2"); --map MAP also adds the map to the level
        registry under its file's stem, as `camdirector level add STEM MAP` does (for the same
        player size, precompute/tracks/track_settings.py's PLAYER_HEIGHT_M and PLAYER_RADIUS_M),
        and records that name. Writes the match (evaluation/match/match_file.py) and prints one
        JSON object: players (name, team), frames, duration_s, kills.
        All or nothing: the demo is read and the match written beside OUT before the map is
        added, and OUT appears once the map is in; a failed import adds no level and leaves no
        file. An error names the file it is about (the demo, the map or OUT) and what is wrong.
        Exit status: 0 ok, 1 the level registry is unavailable, 2 bad arguments or a demo or map
        that cannot be read, or a match file that cannot be written.

Kept light at import, as evaluation/match/sim_cli.py: numpy and the readers load when the command runs.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import shutil
import sys
from collections.abc import Iterator
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
    from camdirector.precompute.tracks.registry import LevelsUnavailable, default_data_dir

    level = args.level or (map_level_name(args.map) if args.map else None)
    part = args.out.with_name(args.out.name + ".part")  # the match, until the map is in
    made: list[Path] = []  # folders this run created (for OUT, for the registry), removed if it fails
    try:
        with _failing_file(args.demo):
            match = importer_for(args.demo).read(args.demo, level=level, rate_hz=args.rate_hz)
        with _failing_file(args.out):
            made += _missing_folders(args.out.parent)
            args.out.parent.mkdir(parents=True, exist_ok=True)
            save_match(match, part)
        if args.map:
            made += _missing_folders(args.data_dir or default_data_dir())  # the registry makes them
            with _failing_file(args.map):
                add_map(args.map, map_level_name(args.map), args.data_dir)
        with _failing_file(args.out):
            part.replace(args.out)
    except LevelsUnavailable as exc:
        _undo(part, made)
        print(f"camdirector import-match: {exc}", file=sys.stderr)
        return 1
    except _FileError as exc:
        _undo(part, made)
        print(f"camdirector import-match: {exc}", file=sys.stderr)
        return 2
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


class _FileError(Exception):
    """A file the command could not read or write: the message is "FILE: what is wrong"."""


@contextlib.contextmanager
def _failing_file(path: Path) -> Iterator[None]:
    """Turns a failure to read or write `path` into _FileError naming it once: OSError (gzip's
    BadGzipFile among them; the system's reason, and the path it was about where that is another),
    EOFError and ValueError (whose message names the file already where a reader's does:
    cs2_demo.Cs2DemoError)."""
    try:
        yield
    except (OSError, EOFError, ValueError) as exc:
        text = str(exc)
        if isinstance(exc, OSError) and exc.strerror:
            text = exc.strerror if exc.filename in (None, str(path)) else f"{exc.strerror}: {exc.filename}"
        raise _FileError(text if text.startswith(f"{path}: ") else f"{path}: {text}") from None


def _missing_folders(folder: Path) -> list[Path]:
    """[the outermost of folder and its parents that does not exist yet], [] where folder exists:
    removing it removes every folder a run makes for folder."""
    return [f for f in reversed((folder, *folder.parents)) if not f.exists()][:1]


def _undo(part: Path, made: list[Path]) -> None:
    """Removes what a failed run wrote: the unfinished match, and the folders it made with all
    they hold (nothing but this run's: they were not there before it)."""
    with contextlib.suppress(FileNotFoundError, NotADirectoryError):  # never written
        part.unlink()
    for folder in made:
        shutil.rmtree(folder, ignore_errors=True)


def _games() -> str:
    """What the importers read, for the help: "QuakeWorld .mvd/.mvd.gz, CS2 .dem"."""
    return ", ".join(f"{importer.name} {'/'.join(importer.suffixes)}" for importer in IMPORTERS)


def map_level_name(map_path: Path) -> str:
    """The name --map registers the map under: its file's stem ("dm2" for dm2.bsp)."""
    return map_path.name.split(".")[0]


def add_map(map_path: Path, name: str, data_dir: Path | None) -> None:
    """Adds the map to the level registry under name, as `camdirector level add` does, for the
    same player (track_settings.py)."""
    from camdirector.precompute.tracks.registry import LevelRegistry
    from camdirector.precompute.tracks.track_settings import PLAYER_HEIGHT_M, PLAYER_RADIUS_M

    with LevelRegistry(data_dir) as registry:
        registry.add_level(name, map_path, agent_height_m=PLAYER_HEIGHT_M, agent_radius_m=PLAYER_RADIUS_M)
