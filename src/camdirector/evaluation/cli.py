"""The evaluation's subcommands of `camdirector`, one per rig's evaluation: `eval` (TORIC, the
paper's scenarios and suite: toric/cli.py), `eval-graph` (TRACKS: tracks/cli.py), `match-sim` and
`eval-match` (MATCH: match/sim_cli.py, match/eval_cli.py).

`add_parsers(subparsers)` registers them on the `camdirector` parser; each sets its own `handler`.
"""

from __future__ import annotations

import argparse
import sys

from camdirector.evaluation.match.eval_cli import add_parser as add_eval_match_parser
from camdirector.evaluation.match.sim_cli import add_parser as add_match_sim_parser
from camdirector.evaluation.toric.cli import add_parser as add_eval_parser
from camdirector.evaluation.tracks.cli import add_parser as add_eval_graph_parser


def add_parsers(subparsers) -> None:
    """Registers `eval`, `match-sim`, `eval-match` and `eval-graph` on an argparse subparsers object;
    args.handler(args) runs it."""
    add_eval_parser(subparsers)
    add_match_sim_parser(subparsers)
    add_eval_match_parser(subparsers)
    add_eval_graph_parser(subparsers)


def main(argv: list[str] | None = None) -> int:
    """Standalone entry point: python -m camdirector.evaluation.cli eval ..."""
    parser = argparse.ArgumentParser(prog="camdirector")
    add_parsers(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.handler(args)


if __name__ == "__main__":
    sys.exit(main())
