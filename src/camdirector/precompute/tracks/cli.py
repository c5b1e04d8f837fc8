"""`camdirector level add|list|remove`.

    camdirector level add NAME LEVEL.(obj|glb|bsp) [--navmesh NAV.(obj|glb)] [--scale M_PER_UNIT]
                          [--agent-height M] [--agent-radius M] [--tenant T] [--data-dir DIR] [--records-url URL]
        precomputes the level into the registry; prints the record (JSON) with stage timings. The
        agent is the players the level is for: by default the one size `import-match --map` uses
        too (track_settings.py, PLAYER_HEIGHT_M and PLAYER_RADIUS_M), so a map gets one camera graph.
    camdirector level list [--tenant T] [--data-dir DIR] [--records-url URL]
        prints one JSON object per level.
    camdirector level remove NAME [--tenant T] [--data-dir DIR] [--records-url URL]
        removes a level from the registry (a running server's sessions on it keep their copy).
--tenant: whose level (registry.py: each tenant has its own names; the tenant of the keys whose
sessions use it). Default `default`, the tenant of a server without keys and of its first admin key.
--records-url: where the registry's index lives, as `camdirector serve --job-store` says for the
nodes: empty for SQLite in the data directory, or the postgresql:// URL a cluster's nodes share
(with --data-dir the folder they share). Default: $CAMDIRECTOR_JOB_STORE, the variable `serve`
reads, so a shell set up for the nodes sees their levels.
Exit status: 0 ok, 1 failed, 2 bad arguments or input.

`add_parsers(subparsers)` registers `level` on the `camdirector` parser; each subcommand sets `handler`.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from camdirector.precompute.tracks.track_settings import PLAYER_HEIGHT_M, PLAYER_RADIUS_M

if TYPE_CHECKING:  # the registry is imported where a command needs it
    from camdirector.precompute.tracks.registry import LevelRecord, LevelRegistry

_RECORDS_URL_HELP = (
    "the registry's index: postgresql://... (a cluster's --job-store) or empty for SQLite in "
    "the data dir (default: $CAMDIRECTOR_JOB_STORE)"
)


def add_records_url_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--records-url", dest="records_url", default=None, help=_RECORDS_URL_HELP)


def _add_tenant_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--tenant", default="default", help="whose level: the tenant of the keys whose sessions use it (default: default)"
    )


def registry_from_args(args: argparse.Namespace) -> LevelRegistry:
    """The registry that --data-dir and --records-url (else $CAMDIRECTOR_JOB_STORE) name."""
    from camdirector.precompute.tracks.registry import LevelRegistry

    url = args.records_url if args.records_url is not None else os.environ.get("CAMDIRECTOR_JOB_STORE", "")
    return LevelRegistry(args.data_dir, url)


def add_parsers(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Registers `level`; args.handler(args) runs the command."""
    level = subparsers.add_parser("level", help="precomputed levels for the TRACKS rig")
    sub = level.add_subparsers(dest="level_command", required=True)
    p = sub.add_parser("add", help="precompute a level into the registry")
    p.add_argument("name")
    p.add_argument("level", type=Path, help="level mesh, .obj or .glb, or a Quake .bsp map (read in metres)")
    p.add_argument("--navmesh", type=Path, help="navigation mesh (.obj or .glb); derived when absent")
    p.add_argument(
        "--scale",
        type=float,
        default=1.0,
        help="metres per level unit (default 1; a .bsp is read in metres already, so it multiplies those)",
    )
    p.add_argument(
        "--agent-height",
        dest="agent_height",
        type=float,
        default=PLAYER_HEIGHT_M,
        help=f"the players' height, m (default {PLAYER_HEIGHT_M:g}, as import-match --map: track_settings.py)",
    )
    p.add_argument(
        "--agent-radius",
        dest="agent_radius",
        type=float,
        default=PLAYER_RADIUS_M,
        help=f"the players' radius, m (default {PLAYER_RADIUS_M:g}, as import-match --map)",
    )
    p.add_argument("--data-dir", dest="data_dir", type=Path, help="registry folder (default: per-user data dir)")
    add_records_url_argument(p)
    _add_tenant_argument(p)
    p.set_defaults(handler=run_level_add)
    p = sub.add_parser("list", help="list registered levels")
    p.add_argument("--data-dir", dest="data_dir", type=Path)
    add_records_url_argument(p)
    _add_tenant_argument(p)
    p.set_defaults(handler=run_level_list)
    p = sub.add_parser("remove", help="remove a level from the registry")
    p.add_argument("name")
    p.add_argument("--data-dir", dest="data_dir", type=Path)
    add_records_url_argument(p)
    _add_tenant_argument(p)
    p.set_defaults(handler=run_level_remove)


def _record_json(record: LevelRecord) -> dict[str, Any]:
    return {
        "name": record.name,
        "tenant": record.tenant,
        "artifact": str(record.artifact_path),
        "format_version": record.format_version,
        "source": record.source_path,
        "navmesh": record.navmesh_path,
        "m_per_unit": record.m_per_unit,
        "agent_height_m": record.agent_height_m,
        "agent_radius_m": record.agent_radius_m,
        "counts": record.counts,
        "timings_ms": {k: round(v, 1) for k, v in record.timings_ms.items()},
    }


def run_level_add(args: argparse.Namespace) -> int:
    from camdirector.precompute.tracks.registry import LevelsUnavailable

    def progress(fraction: float) -> None:
        print(f"camdirector level add: {100 * fraction:.0f}%", file=sys.stderr)

    try:
        with registry_from_args(args) as registry:
            record = registry.add_level(
                args.name,
                args.level,
                args.navmesh,
                scale=args.scale,
                agent_height_m=args.agent_height,
                agent_radius_m=args.agent_radius,
                progress=progress,
                tenant=args.tenant,
            )
    except LevelsUnavailable as exc:
        print(f"camdirector level add: {exc}", file=sys.stderr)
        return 1
    except (OSError, ValueError) as exc:
        print(f"camdirector level add: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(_record_json(record)))
    return 0


def run_level_list(args: argparse.Namespace) -> int:
    from camdirector.infra.tenants import check_tenant
    from camdirector.precompute.tracks.registry import LevelsUnavailable

    try:
        with registry_from_args(args) as registry:
            check_tenant(args.tenant)  # a bad one is an error, not an empty list
            records = registry.list(args.tenant)
    except (LevelsUnavailable, ValueError) as exc:
        print(f"camdirector level list: {exc}", file=sys.stderr)
        return 1 if isinstance(exc, LevelsUnavailable) else 2
    for record in records:
        print(json.dumps(_record_json(record)))
    return 0


def run_level_remove(args: argparse.Namespace) -> int:
    from camdirector.infra.tenants import check_tenant
    from camdirector.precompute.tracks.registry import LevelsUnavailable

    try:
        with registry_from_args(args) as registry:
            check_tenant(args.tenant)
            removed = registry.delete(args.name, args.tenant)
    except (LevelsUnavailable, ValueError) as exc:
        print(f"camdirector level remove: {exc}", file=sys.stderr)
        return 1 if isinstance(exc, LevelsUnavailable) else 2
    if not removed:
        print(f"camdirector level remove: no level named {args.name!r}", file=sys.stderr)
        return 2
    return 0
