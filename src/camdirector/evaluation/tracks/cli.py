"""`camdirector eval-graph`: the paper's comparison of our camera graph with probabilistic roadmaps
(Section 6.2) on a registered level.

    camdirector eval-graph LEVEL [--data-dir DIR] [--records-url URL] [--json OUT] [--plot OUT.png] [--seed N]
        our graph against PRMs on a registered level along an actor route: the Recast test cases
        (TestCases/nav_mesh_test.txt beside the level file) where they exist, else an A* path on
        the navmesh; prints the table as JSON. Each graph's row counts the frames that show the
        actor (`visible`: inside the frame and unoccluded) apart from those with a clear line of
        sight to it (`line_of_sight`), by evaluation/tracks/measure.py.
Exit status: 0 ok, 1 the registry is unreachable, 2 bad arguments or an unknown level.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from camdirector.precompute.tracks.cli import add_records_url_argument, registry_from_args


def add_parser(subparsers) -> None:
    """Registers `eval-graph`; args.handler(args) runs it."""
    p = subparsers.add_parser("eval-graph", help="our camera graph against probabilistic roadmaps on a level")
    p.add_argument("level", help="registered level name")
    p.add_argument("--data-dir", dest="data_dir", type=Path)
    add_records_url_argument(p)
    p.add_argument("--json", type=Path, help="write the table here")
    p.add_argument("--plot", type=Path, help="top views of the graphs, route and camera paths (PNG)")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(handler=run_eval_graph)


def route_for(artifact, record, rng):
    """The actor route: Recast test cases beside the level file where present, else an A* path."""
    import numpy as np

    from camdirector.evaluation.tracks.route import FRAME_RATE_HZ, WALK_SPEED_M_S, NavmeshPaths, read_recast_queries, walk
    from camdirector.geometry.meshes import TriMesh

    paths = NavmeshPaths(TriMesh(artifact.navmesh_vertices, artifact.navmesh_faces), artifact.settings)
    cases = Path(record.source_path).parent / "TestCases" / "nav_mesh_test.txt"
    polyline = None
    if cases.is_file() and cases.read_text().find(Path(record.source_path).name) >= 0:
        legs = [paths.path(s * record.m_per_unit, e * record.m_per_unit) for s, e in read_recast_queries(cases)[:3]]
        legs = [leg for leg in legs if leg is not None]
        if legs:
            polyline = np.vstack(legs)
    if polyline is None:
        polyline = paths.random_path(rng, 60.0)
    return walk(polyline, WALK_SPEED_M_S, FRAME_RATE_HZ)


def run_eval_graph(args) -> int:
    import numpy as np

    from camdirector.evaluation.tracks.compare import compare_with_prm
    from camdirector.precompute.tracks.registry import LevelsUnavailable

    try:
        with registry_from_args(args) as registry:
            artifact = registry.load(args.level)
            record = registry.get(args.level)
    except LevelsUnavailable as exc:
        print(f"camdirector eval-graph: {exc}", file=sys.stderr)
        return 1
    except (KeyError, ValueError) as exc:
        print(f"camdirector eval-graph: {exc}", file=sys.stderr)
        return 2
    rng = np.random.default_rng(args.seed)
    route = route_for(artifact, record, rng)
    result = compare_with_prm(artifact, route, rng, plot_path=args.plot)
    result = {"level": args.level, "stage_timings_ms": artifact.timings_ms, **result}
    text = json.dumps(result, indent=1)
    if args.json is not None:
        args.json.write_text(text)
    print(text)
    return 0
