"""`camdirector match-sim`: a bot match on a registered level, written as a match file.

    camdirector match-sim --level NAME [--players 10] [--minutes 5] [--seed 0] --out FILE.npz
                          [--data-dir DIR] [--rate-hz 60]
        simulates two teams of bots on the level's navmesh (evaluation/match/sim.py) and writes
        the match (evaluation/match/match_file.py); prints one JSON object: the counts of events,
        kills per minute and the simulation's wall time. The same seed gives the same file.
        Exit status: 0 ok, 2 bad arguments or unknown level.

Kept light at import, as evaluation/cli.py: numpy and the simulator load when the command runs.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def add_parser(subparsers) -> None:
    """Registers `match-sim` on an argparse subparsers object; args.handler(args) runs it."""
    p = subparsers.add_parser(
        "match-sim",
        help="simulate a bot match on a registered level and write it as a match file",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--level", required=True, help="registered level name (camdirector level add)")
    p.add_argument("--players", type=int, default=10, help="players, both teams together, 2 to 64 (default 10)")
    p.add_argument("--minutes", type=float, default=5.0, help="length of the match, minutes (default 5)")
    p.add_argument("--seed", type=int, default=0, help="seed of the match (default 0)")
    p.add_argument("--out", type=Path, required=True, help="match file to write (.npz)")
    p.add_argument("--data-dir", dest="data_dir", type=Path, help="registry folder (default: per-user data dir)")
    p.add_argument("--rate-hz", dest="rate_hz", type=float, default=60.0, help="frames per second (default 60)")
    p.set_defaults(handler=run_match_sim)


def run_match_sim(args: argparse.Namespace) -> int:
    """Runs `camdirector match-sim` from parsed arguments; returns the exit status."""
    import numpy as np

    from camdirector.evaluation.match.match_file import save_match
    from camdirector.evaluation.match.sim import SimSettings, simulate_match
    from camdirector.precompute.tracks.registry import LevelRegistry

    try:
        if not args.minutes > 0:
            raise ValueError("--minutes must be positive")
        settings = SimSettings(rate_hz=args.rate_hz, ai_rate_hz=min(SimSettings.ai_rate_hz, args.rate_hz))
        artifact = LevelRegistry(args.data_dir).load(args.level)
        start = time.perf_counter()
        match = simulate_match(
            artifact, args.level, args.players, 60.0 * args.minutes, np.random.default_rng(args.seed), args.seed, settings
        )
        wall_s = time.perf_counter() - start
    except KeyError as exc:
        print(f"camdirector match-sim: {exc.args[0]}", file=sys.stderr)
        return 2
    except ValueError as exc:
        print(f"camdirector match-sim: {exc}", file=sys.stderr)
        return 2
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save_match(match, args.out)
    counts = {kind: sum(e.kind == kind for e in match.events) for kind in ("kill", "damage", "objective")}
    print(
        json.dumps(
            {
                "level": args.level,
                "players": args.players,
                "seed": args.seed,
                "frames": len(match.time_s),
                "rate_hz": settings.rate_hz,
                "minutes": args.minutes,
                "events": counts,
                "kills_per_min": round(counts["kill"] / args.minutes, 2),
                "sim_wall_s": round(wall_s, 2),
                "out": str(args.out),
            }
        )
    )
    return 0
