"""`camdirector eval`: one scenario with one visibility mode, or the paper's comparison suite.

    camdirector eval --scenario FILE [--visibility MODE] [--json OUT] [--plot OUT.png] [--server ADDR]
                     [--duration S] [--map-resolution N] [--map-backend AUTO|GL|EMBREE]
        prints the run's summary as one JSON object; --json writes it with the per-frame series.
        Exit status: 0 ok, 1 the run failed, 2 bad arguments or scenario, 3 the server does not
        implement the mode (UNIMPLEMENTED).
    camdirector eval --suite {paper,all} --out DIR [--modes M1,M2] [--server ADDR] [--duration S]
                     [--no-plots]
        prints the comparison tables; writes DIR/suite.json, DIR/table.txt, DIR/<scene>.png and
        DIR/runs/<scene>__<mode>.{json,png}. Unimplemented modes are listed as unavailable.
        Exit status: 0 unless a run failed (1) or the arguments are bad (2).

Without --server, a `camdirector serve` subprocess is started on a free loopback port for the
run. `add_parser(subparsers)` registers the subcommand on the `camdirector` parser
(evaluation/cli.py); its `handler` default is `run_eval`.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

# Kept light at import (camdirector's own CLI imports this module to register the subcommand):
# the evaluation modules, with numpy, scipy and matplotlib behind them, load when eval runs, and
# with them the suite's modes (toric/suite.py `MODES`, read from the style's VisibilityMode).


def add_parser(subparsers) -> None:
    """Registers `eval` on an argparse subparsers object; args.handler(args) runs it."""
    p = subparsers.add_parser(
        "eval",
        help="replay scenarios through a real session and measure visibility and smoothness",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("--scenario", type=Path, help="a scenario file (evaluation/scenario_file.py documents the format)")
    which.add_argument("--suite", choices=("paper", "all"), help="every mode on the paper's scenes, or on all shipped ones")
    p.add_argument(
        "--visibility", default="FRAMING_ONLY", metavar="MODE", help="--scenario: a VisibilityMode name (default FRAMING_ONLY)"
    )
    p.add_argument(
        "--modes",
        help="--suite: comma-separated modes (default: every VisibilityMode, the paper's "
        "RAYCAST, NO_ANTICIPATION, ANTICIPATION first)",
    )
    p.add_argument("--json", type=Path, help="--scenario: write the result with per-frame series here")
    p.add_argument("--plot", type=Path, help="--scenario: draw visibility, speed and a top view here (PNG)")
    p.add_argument("--out", type=Path, help="--suite: output folder")
    p.add_argument("--server", help="gRPC HOST:PORT of a running server (default: start one)")
    p.add_argument("--duration", type=float, help="simulated seconds to run (default: each scenario's own)")
    p.add_argument("--no-plots", action="store_true", help="--suite: write no figures")
    p.add_argument(
        "--map-resolution",
        type=int,
        default=0,
        help="--scenario: occlusion map texels per side for the map modes (default: the server's, 64)",
    )
    p.add_argument(
        "--map-backend",
        choices=("AUTO", "GL", "EMBREE"),
        default="AUTO",
        help="--scenario: how the map modes compute their maps (default AUTO)",
    )
    p.set_defaults(handler=run_eval)


def _modes(text: str | None) -> list[str]:
    from camdirector.evaluation.scenario import visibility_mode
    from camdirector.evaluation.toric.suite import MODES

    if not text:
        return list(MODES)
    names = [m.strip().upper() for m in text.split(",") if m.strip()]
    for name in names:
        visibility_mode(name)  # ValueError names the known modes
    return names


def run_eval(args: argparse.Namespace) -> int:
    """Runs `camdirector eval` from parsed arguments; returns the exit status."""
    from camdirector.evaluation.scenario import visibility_mode
    from camdirector.evaluation.scenario_file import ScenarioError, load_scenario
    from camdirector.evaluation.toric.run import plot_run, run_scenario, write_json
    from camdirector.evaluation.toric.suite import print_progress, run_suite, suite_scenarios

    if args.duration is not None and not args.duration > 0:
        print("camdirector eval: --duration must be positive", file=sys.stderr)
        return 2
    try:
        if args.suite:
            if args.out is None:
                print("camdirector eval: --suite needs --out DIR", file=sys.stderr)
                return 2
            modes = _modes(args.modes)
            suite = run_suite(
                suite_scenarios(args.suite),
                modes,
                out_dir=args.out,
                server=args.server,
                duration_s=args.duration,
                plots=not args.no_plots,
                progress=print_progress,
            )
            print(suite.table())
            print()
            print(suite.stage_table())
            return 1 if any(r.status == "error" for r in suite.results) else 0
        mode = args.visibility.upper()
        visibility_mode(mode)
        scenario = load_scenario(args.scenario)
    except (ScenarioError, ValueError) as exc:
        print(f"camdirector eval: {exc}", file=sys.stderr)
        return 2
    result = run_scenario(
        scenario,
        mode,
        server=args.server,
        duration_s=args.duration,
        map_resolution=args.map_resolution,
        map_backend=args.map_backend,
    )
    if args.json:
        write_json(result, args.json)
    if args.plot:
        plot_run(result, args.plot)
    print(json.dumps(result.as_dict(series=False)))
    return {"ok": 0, "unavailable": 3}.get(result.status, 1)
