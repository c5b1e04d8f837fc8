"""Toric space, Python against compiled: what one call costs in geometry/toric.py and in its twin
camdirector._native (native/src/toric.rs, issue 43).

    python -m load_tests.toric_native [--blocks 300] [--calls 50] [--json FILE]

Cases, each called the way the TORIC rig calls it (A, B as float64 arrays, screen points as
tuples, a camera.Lens): `make_torus`, `torus_position` at 1 place (float theta, phi) and at 390
(arrays, a shot's place search), and `compose_pose`. Each is timed in blocks of --calls calls
(perf_counter_ns around the block, divided by the calls), --blocks blocks per case, the cases
round-robin so that the machine's load falls on all alike; reported per case and side: median and
p99 of the per-call microseconds over the blocks. The floor, measured the same way in the same
run: `empty_python`, a Python function that does nothing, and `empty_native`, _native.theta_max
(one subtraction: a compiled call's own cost, argument parsing and return included). Ratios:
python over native per case (the speed-up; above 1 the compiled one is faster), raw and with each
side's floor taken off. Prints JSON (and writes it to --json); asserts nothing.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from camdirector import _native as native
from camdirector.geometry import toric
from camdirector.geometry.camera import Lens
from load_tests.report import emit, speedup, summary

PLACES = 390  # torus_position's batched case: a shot's place search


def _empty(_: float) -> None:
    """The Python floor: a call that does nothing."""


def cases(native) -> dict[str, Callable[[], object]]:
    """name -> a call with its arguments bound; names end in _python or _native."""
    rng = np.random.default_rng(43)
    a, b = rng.normal(size=3) * 20.0, rng.normal(size=3) * 20.0
    lens, sa, sb = Lens(50.0, 16.0 / 9.0), (-0.35, 0.1), (0.3, -0.05)
    alpha = toric.composition_angle(sa, sb, lens)
    torus, twin = toric.make_torus(a, b, alpha), native.make_torus(a, b, alpha)
    theta, phi = 0.4 * toric.theta_max(alpha), 0.7
    thetas = rng.uniform(0.0, toric.theta_max(alpha), PLACES)
    phis = rng.uniform(-math.pi, math.pi, PLACES)
    return {
        "empty_python": lambda: _empty(alpha),
        "empty_native": lambda: native.theta_max(alpha),
        "make_torus_python": lambda: toric.make_torus(a, b, alpha),
        "make_torus_native": lambda: native.make_torus(a, b, alpha),
        "torus_position_1_python": lambda: toric.torus_position(torus, theta, phi),
        "torus_position_1_native": lambda: native.torus_position(twin, theta, phi),
        f"torus_position_{PLACES}_python": lambda: toric.torus_position(torus, thetas, phis),
        f"torus_position_{PLACES}_native": lambda: native.torus_position(twin, thetas, phis),
        "compose_pose_python": lambda: toric.compose_pose(torus, theta, phi, sa, sb, lens),
        "compose_pose_native": lambda: native.compose_pose(twin, theta, phi, sa, sb, lens),
    }


def measure(calls: dict[str, Callable[[], object]], blocks: int, per_block: int) -> dict[str, dict]:
    """name -> summary of per-call microseconds over `blocks` timed blocks of `per_block` calls."""
    times_us: dict[str, list[float]] = {name: [] for name in calls}
    for call in calls.values():  # warm-up: imports, caches, the first allocation
        for _ in range(per_block):
            call()
    for _ in range(blocks):
        for name, call in calls.items():
            start = time.perf_counter_ns()
            for _ in range(per_block):
                call()
            times_us[name].append((time.perf_counter_ns() - start) / per_block / 1e3)
    return {name: summary(values) for name, values in times_us.items()}


def ratios(per_call: dict[str, dict]) -> dict[str, dict]:
    """Per case: its speed-up (report.speedup)."""
    return {
        name.removesuffix("_python"): speedup(per_call, name.removesuffix("_python"))
        for name in per_call
        if name.endswith("_python") and not name.startswith("empty")
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--blocks", type=int, default=300, help="timed blocks per case")
    parser.add_argument("--calls", type=int, default=50, help="calls per timed block")
    parser.add_argument("--json", type=Path, help="also write the JSON here")
    args = parser.parse_args(argv)
    per_call = measure(cases(native), args.blocks, args.calls)
    emit(
        {
            "benchmark": "toric_native",
            "blocks": args.blocks,
            "calls_per_block": args.calls,
            "places_batched": PLACES,
            "per_call_us": per_call,
            "speedup": ratios(per_call),
        },
        args.json,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
