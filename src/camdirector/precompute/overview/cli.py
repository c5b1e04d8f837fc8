"""`camdirector overview` and `camdirector eval-overview` (issue 5).

    camdirector overview CLIP.bvh --out DIR [--scale M] [--skip-frames N] [--aspect A] [--seed S]
        writes DIR/result.json (the REST result schema), DIR/preview.mp4, DIR/contact-sheet.png;
        prints a one-line JSON summary (shots, metrics, timings in ms).
        Exit status: 0 ok, 2 bad arguments or a clip that cannot be read or planned.
    camdirector eval-overview CLIP... [--skip-frames N ...] [--seed S] [--param NAME=VALUE ...]
                              [--json OUT] [--plot DIR]
        the paper's Figure 10 per clip: E, E_external and V (as -sum V) of our path, the static
        camera the annealing starts from (best on E_external) and the smoothed per-frame greedy
        path, each divided by |the best static camera's score on that attribute| (-1 = the best
        static camera, lower is better); the last columns say whether ours is strictly better
        than every static camera and than the greedy path on both E and E_external; --plot
        writes DIR/<clip>.png, the Figure 9 quality per frame and shots; --param sets one of
        the paper's parameters the REST API accepts (e.g. split_quality=0.9), default: the
        paper's. Prints a table. Exit status: 0 ok, 2 bad input.

`add_parsers(subparsers)` registers both; each sets `handler` (call `args.handler(args)`).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path


def add_parsers(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Registers `overview` and `eval-overview`; args.handler(args) runs them."""
    p = subparsers.add_parser(
        "overview",
        help="plan a multi-shot overview camera for a BVH clip",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("clip", type=Path, help="BVH file")
    p.add_argument("--out", type=Path, required=True, help="output folder (created)")
    p.add_argument("--scale", type=float, help="metres per file unit (default: inferred)")
    p.add_argument(
        "--skip-frames", dest="skip_frames", type=int, default=0, help="leading frames to ignore, e.g. a T-pose (default 0)"
    )
    p.add_argument("--aspect", type=float, help="frame width / height (default 16/9)")
    p.add_argument("--seed", type=int, default=0, help="annealing random seed (default 0)")
    p.set_defaults(handler=run_overview)

    p = subparsers.add_parser("eval-overview", help="Figure 10 comparison of overview paths")
    p.add_argument("clips", type=Path, nargs="+", help="BVH files")
    p.add_argument(
        "--skip-frames",
        dest="skip_frames",
        type=int,
        nargs="+",
        default=[0],
        help="leading frames to skip: one value for all clips or one per clip",
    )
    p.add_argument("--scale", type=float, help="metres per file unit for every clip (default: inferred)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="one of the paper's parameters (the REST form fields), repeatable",
    )
    p.add_argument("--json", type=Path, help="write the comparison here")
    p.add_argument("--plot", type=Path, help="folder for the Figure 9 plots, one PNG per clip")
    p.set_defaults(handler=run_eval_overview)


def _error(command: str, message: str) -> int:
    print(f"camdirector {command}: {message}", file=sys.stderr)
    return 2


def run_overview(args: argparse.Namespace) -> int:
    import numpy as np

    from camdirector.precompute.overview.job import (
        comparison_metrics,
        load_clip_bytes,
        settings_from_params,
        write_overview_outputs,
    )
    from camdirector.precompute.overview.pipeline import plan_overview

    try:
        data = args.clip.read_bytes()
        t = time.perf_counter()
        clip = load_clip_bytes(data, scale=args.scale, skip_frames=args.skip_frames)
        parse_ms = (time.perf_counter() - t) * 1e3
        settings = settings_from_params({"aspect": args.aspect})
        result = plan_overview(clip, settings, np.random.default_rng(args.seed))
    except (OSError, ValueError) as exc:
        return _error("overview", f"{args.clip}: {exc}")
    args.out.mkdir(parents=True, exist_ok=True)
    # Written into a sibling temp folder and moved into place file by file: an interrupted run
    # leaves the previous outputs or none, never a half-written file.
    tmp = Path(tempfile.mkdtemp(prefix=".overview-", dir=args.out))
    try:
        metrics = comparison_metrics(result)
        timings = {"parse_bvh": parse_ms, **result.timings_ms}
        timings.update(write_overview_outputs(clip, result, tmp, skip_frames=args.skip_frames, metrics=metrics))
        for f in tmp.iterdir():
            os.replace(f, args.out / f.name)
    finally:
        for f in tmp.iterdir():
            f.unlink()
        tmp.rmdir()
    print(
        json.dumps(
            {
                "clip": str(args.clip),
                "out": str(args.out),
                "frames": clip.frame_count,
                "shots": [[int(a), int(b)] for a, b in result.shots],
                "metrics": metrics,
                "timings_ms": {k: round(v, 1) for k, v in timings.items()},
            }
        )
    )
    return 0


def run_eval_overview(args: argparse.Namespace) -> int:
    import numpy as np

    from camdirector.precompute.overview.bvh import load_motion
    from camdirector.precompute.overview.evaluation import compare_with_baselines, plot_quality
    from camdirector.precompute.overview.job import PAPER_PARAMETERS, settings_from_params
    from camdirector.precompute.overview.pipeline import plan_overview

    params = {}
    for item in args.param:
        name, sep, value = item.partition("=")
        if not sep or name not in PAPER_PARAMETERS:
            return _error(
                "eval-overview", f"--param {item!r}: expected NAME=VALUE with NAME one of {', '.join(PAPER_PARAMETERS)}"
            )
        try:
            params[name] = float(value)
        except ValueError:
            return _error("eval-overview", f"--param {item!r}: {value!r} is not a number")
    try:
        settings = settings_from_params(params)
    except (TypeError, ValueError) as exc:
        return _error("eval-overview", f"--param: {exc}")
    skips = args.skip_frames
    if len(skips) not in (1, len(args.clips)):
        return _error("eval-overview", "--skip-frames takes one value or one per clip")
    skips = skips * len(args.clips) if len(skips) == 1 else skips
    if args.plot is not None:
        args.plot.mkdir(parents=True, exist_ok=True)
    table, rows = {}, []
    for path, skip in zip(args.clips, skips):
        try:
            clip = load_motion(path, scale_m_per_unit=args.scale, skip_frames=skip)
            result = plan_overview(clip, settings, np.random.default_rng(args.seed))
        except (OSError, ValueError) as exc:
            return _error("eval-overview", f"{path}: {exc}")
        cmp = compare_with_baselines(result)
        name = path.stem
        entry = cmp.as_dict()
        entry["frames"] = clip.frame_count
        entry["shots"] = int(len(result.shots))
        entry["beats_both_on_E_and_E_external"] = cmp.beats_best_static and cmp.beats_greedy
        table[name] = entry
        if args.plot is not None:
            plot_quality(result, args.plot / f"{name}.png", name)
        rows.append((name, clip.frame_count, len(result.shots), cmp))
    print(
        f"{'clip':32s} {'frames':>6s} {'shots':>5s}   {'E ours/static/greedy':>26s}   "
        f"{'E_ext ours/static/greedy':>26s}   {'V ours/static/greedy':>23s}   beats static/greedy"
    )
    for name, n, s, c in rows:
        print(
            f"{name:32s} {n:6d} {s:5d}   {c.ours.e:7.3f} {c.static.e:7.3f} {c.greedy.e:10.4g}   "
            f"{c.ours.e_external:8.3f} {c.static.e_external:8.3f} {c.greedy.e_external:8.3f}   "
            f"{c.ours.neg_v:7.3f} {c.static.neg_v:7.3f} {c.greedy.neg_v:7.3f}   "
            f"{'yes' if c.beats_best_static else 'no':>6s} {'yes' if c.beats_greedy else 'no':>6s}"
        )
    if args.json is not None:
        args.json.write_text(
            json.dumps(
                {
                    "normalisation": "value / |best static camera's value on that attribute|; lower is better; V as -sum V",
                    "clips": table,
                },
                indent=1,
            )
        )
    return 0
