"""The match directors on real matches (issue 29, "Done when"): every development QuakeWorld demo that
has its map, imported (`import-match`), its map added as a level with the Quake player's size, and
`eval-match` run on it: our director, HLTV's and the autotrack, the ceilings, with a delay; and
the same on a `match-sim` bot match of each shared level (../shared/data/levels: 10 players, seed
1, as long as --minutes, default 3), named sim_<level>.

    python -m load_tests.real_matches [--minutes 3] [--delay 10] [--rate-hz 30] [--twice] [--paced]
                                      [--only 4on4_dm2,sim_zdm2,...] [--directors planned,...]
                                      [--json out/rm.json] [--markdown out/rm.md]

--paced sends the frames in real time (eval-match --paced: the same program, a live session's
compute times; a 3-minute match takes 3 minutes and 10 s per director).
--directors runs only the named directors (registered names; default every one): `--directors
planned` is how docs/casting.md's before/after tables of our director are measured.
--twice runs each match a second time from scratch (the level added anew in another folder, a new
server) and reports whether every director's program digest is the same. The two held-out matches
of the issue are not in this list and must never be: they judge the director.
Prints the JSON result; --markdown writes the per-match, per-director table of docs/casting.md.
"""

from __future__ import annotations

import argparse
import gzip
import sys
import tempfile
import time
from pathlib import Path

from load_tests.report import emit

ROOT = Path(__file__).resolve().parents[1]
DEMOS = ROOT / "tests" / "data" / "real_matches"
MAPS = ROOT / "tests" / "data" / "real_maps"
# name -> (demo, map); the 1on1 on tron is left out: no copy of its map was found (real_maps/SOURCES.md)
MATCHES = {
    "4on4_dm2": ("4on4_s_vs_pol_dm2_20241118-2135.mvd.gz", "dm2.bsp.gz"),
    "2on2_frobodm2": ("2on2_sf_vs_red_frobodm2_220104-0915.mvd.gz", "frobodm2.bsp.gz"),
    "duel_bravado": ("duel_holy_vs_dago_bravado_20240426-1659.mvd.gz", "bravado.bsp.gz"),
    "wipeout_q3dm6qw": ("wipeout_red_vs_blue_q3dm6qw_20240406-2028.mvd.gz", "q3dm6qw.bsp.gz"),
}
SHARED_LEVELS = ROOT.parent / "shared" / "data" / "levels"
# name -> level file under ../shared/data/levels: a bot match is simulated on each (match-sim)
SIM_MATCHES = {
    "sim_nav_test": "recast/nav_test.obj",
    "sim_dungeon": "recast/dungeon.obj",
    "sim_undulating": "recast/undulating.obj",
    "sim_zdm2": "sauerbraten/zdm2.obj",
}
KNOWN_MATCHES = (*MATCHES, *SIM_MATCHES)  # every name prepare() takes, the real matches first
SIM_PLAYERS, SIM_SEED = 10, 1
COLUMNS = (
    ("kill coverage", lambda f: f["kill_coverage"]),
    ("first person", lambda f: f["kill_coverage_first_person"]),
    ("program vis.", lambda f: f["program_visibility"]),
    ("height", lambda f: f["shown_height"]["median"]),
    ("height, third person", lambda f: f["shown_height"].get("median_third_person")),
    ("subjects' height", lambda f: f["shown_height"].get("subjects_median")),
    ("tallest / >60%", lambda f: f"{f['shown_height']['max']} / {f['shown_height']['over_60pc']}"),
    ("nobody: overview / other", lambda f: f"{f['nobody_shown']['overview']} / {f['nobody_shown']['other']}"),
    ("candidates showing half", lambda f: f["candidates_showing_half"]["share"]),
    ("shots <2 s", lambda f: f["shots"]["under_2s"]),
    ("shot median s", lambda f: f["shots"]["median"]),
    ("shot max s", lambda f: f["shots"]["max"]),
    (">20 s missing a kill", lambda f: f["long_shots_missing_kills"]),
    (
        "replays: shown / kills with room replayed of with room / live kills missed",
        lambda f: "{s} / {r} of {k} / {m}".format(
            s=f["replays"]["shown"],
            r=f["replays"]["kills_with_room_replayed"],
            k=f["replays"]["kills_with_room"],
            m=f["replays"]["live_kills_missed_for_replay"],
        ),
    ),
    ("cuts/min", lambda f: f["cuts_per_min"]),
    (
        "outside / solid / swept / jumped: program; outside / solid: candidates",
        lambda f: "{o} / {s} / {w} / {j}; {co} / {cs} of {cn}".format(
            o=f["places"]["program"]["outside"],
            s=f["places"]["program"]["solid"],
            w=f["places"]["program"]["swept_through_walls"],
            j=f["places"]["program"]["jumped_without_cut"],
            co=f["places"]["candidates"]["outside"],
            cs=f["places"]["candidates"]["solid"],
            cn=f["places"]["candidates"]["poses"],
        ),
    ),
    ("compute p50/p99 ms", lambda f: f"{f['compute_ms']['median']:.2f} / {f['compute_ms']['p99']:.1f}"),
)


def prepare(name: str, folder: Path, minutes: float | None):
    """The match, imported, with its map added as a level in folder; cut to its first minutes.
    A sim_ match: its shared level added, a bot match of `minutes` (default 3) simulated on it."""
    from camdirector.geometry import quake_frame
    from camdirector.matches.quakeworld_mvd import import_mvd
    from camdirector.precompute.tracks.registry import LevelRegistry

    if name in SIM_MATCHES:
        import numpy as np

        from camdirector.evaluation.match.sim import simulate_match

        level = name.removeprefix("sim_")
        with LevelRegistry(folder / "data") as registry:
            registry.add_level(level, SHARED_LEVELS / SIM_MATCHES[name])
            artifact = registry.load(level)
        return simulate_match(artifact, level, SIM_PLAYERS, 60.0 * (minutes or 3.0), np.random.default_rng(SIM_SEED), SIM_SEED)
    demo, bsp = MATCHES[name]
    level = bsp.split(".")[0]
    map_path = folder / f"{level}.bsp"
    map_path.write_bytes(gzip.decompress((MAPS / bsp).read_bytes()))
    with LevelRegistry(folder / "data") as registry:
        registry.add_level(
            level, map_path, agent_height_m=quake_frame.PLAYER_HEIGHT_M, agent_radius_m=quake_frame.PLAYER_RADIUS_M
        )
    match = import_mvd(gzip.decompress((DEMOS / demo).read_bytes()), level=level, name=demo)
    return match if minutes is None else match.until(match.time_s[0] + 60.0 * minutes)


def run_match(name: str, args) -> dict:
    from camdirector.evaluation.match.evaluate import evaluate_match

    runs = []
    for _ in range(2 if args.twice else 1):
        with tempfile.TemporaryDirectory(prefix=f"real-{name}-") as tmp:
            t0 = time.perf_counter()
            match = prepare(name, Path(tmp), args.minutes)
            result, _ = evaluate_match(
                match,
                args.delay,
                directors=args.directors,
                data_dir=Path(tmp) / "data",
                rate_hz=args.rate_hz,
                seed=0,
                paced=args.paced,
                progress=lambda text: print(f"{name}: {text}", file=sys.stderr, flush=True),
            )
            result["wall_s"] = round(time.perf_counter() - t0, 1)
            runs.append(result)
    out = runs[0]
    if args.twice:
        out["same_program_twice"] = {
            d: runs[0]["directors"][d]["program_sha256"] == runs[1]["directors"][d]["program_sha256"] for d in out["directors"]
        }
    return out


def markdown(results: dict) -> str:
    """One row per match and director: the figures of COLUMNS, the ceilings beside each match."""
    lines = ["| match | director | " + " | ".join(c for c, _ in COLUMNS) + " |", "|---|---|" + "---|" * len(COLUMNS)]
    for name, result in results.items():
        c = result["ceilings"]
        for director, figures in result["directors"].items():
            cells = [str(get(figures)) for _, get in COLUMNS]
            lines.append(f"| {name} | {director} | " + " | ".join(cells) + " |")
        lines.append(
            f"| {name} | ceilings | reference {c['reference_kill_coverage']}, greedy 2-s "
            f"{c['greedy_2s_kill_coverage']} ({c['kills']} kills) |" + " |" * (len(COLUMNS) - 1)
        )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=None, help="each match's first minutes (default: all)")
    parser.add_argument("--delay", type=float, default=10.0, help="broadcast delay, s (default 10)")
    parser.add_argument("--rate-hz", dest="rate_hz", type=float, default=30.0, help="frames a second sent (default 30)")
    parser.add_argument("--twice", action="store_true", help="run each match twice from scratch, compare programs")
    parser.add_argument("--paced", action="store_true", help="send in real time at --rate-hz (issue 41's table; slow)")
    parser.add_argument("--only", default="", help="comma-separated match names (default: all of MATCHES)")
    parser.add_argument("--directors", default="", help="comma-separated director names (default: every one registered)")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--markdown", type=Path)
    args = parser.parse_args(argv)
    from camdirector.pipeline.match.director_registry import registered

    registered_names = [e.name for e in registered()]
    args.directors = [n for n in args.directors.split(",") if n] or None
    strangers = [n for n in args.directors or () if n not in registered_names]
    if strangers:
        print(f"real_matches: unknown director {strangers}; registered: {registered_names}", file=sys.stderr)
        return 2
    known = list(KNOWN_MATCHES)
    names = [n for n in args.only.split(",") if n] or known
    unknown = [n for n in names if n not in known]
    if unknown:
        print(f"real_matches: unknown match {unknown}; known: {known}", file=sys.stderr)
        return 2
    if any(n in SIM_MATCHES for n in names) and not SHARED_LEVELS.is_dir():
        print(f"real_matches: the shared levels are not at {SHARED_LEVELS}", file=sys.stderr)
        return 2
    results = {name: run_match(name, args) for name in names}
    emit({"delay_s": args.delay, "rate_hz": args.rate_hz, "minutes": args.minutes, "matches": results}, args.json)
    if args.markdown is not None:
        args.markdown.parent.mkdir(parents=True, exist_ok=True)
        args.markdown.write_text(markdown(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
