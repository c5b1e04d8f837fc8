"""What every benchmark here does with its result (summaries, printing), and where they find the
shared data by default."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

# ../shared/data beside the repository (never copied into it)
SHARED_DATA_DIR = Path(__file__).resolve().parents[2] / "shared" / "data"


def emit(result: dict, path: Path | None) -> None:
    """Print the result as JSON, and write the same text to path when one is given."""
    text = json.dumps(result, indent=1)
    print(text)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def shared_subfolder(data_dir: Path, name: str, program: str) -> Path | None:
    """data_dir / name, or None after saying on stderr that it is missing (the caller exits 2)."""
    folder = data_dir / name
    if not folder.is_dir():
        print(f"{program}: no {name} folder at {folder} (pass --data-dir)", file=sys.stderr)
        return None
    return folder


def summary(values, scale: float = 1.0) -> dict:
    """median and p99 of values * scale, rounded to 3 decimals, and n: a timing's usual report."""
    a = np.asarray(values, dtype=np.float64) * scale
    return {"median": round(float(np.median(a)), 3), "p99": round(float(np.percentile(a, 99)), 3), "n": len(a)}


def percentiles(values) -> dict:
    """p50, p99 and max of values (all None when there are none): the streaming benchmarks' report."""
    if not len(values):
        return {"p50": None, "p99": None, "max": None}
    a = np.asarray(values, dtype=np.float64)
    return {"p50": float(np.median(a)), "p99": float(np.percentile(a, 99)), "max": float(a.max())}


def speedup(timings: dict[str, dict], case: str) -> dict:
    """The Python twin's median time over the compiled one's for `case` (timings holds summary()s
    named CASE_python and CASE_native, and the floors empty_python and empty_native): raw, and with
    each side's floor taken off first. Above 1 the compiled one is faster."""
    py, native = timings[f"{case}_python"]["median"], timings[f"{case}_native"]["median"]
    floor_py, floor_native = timings["empty_python"]["median"], timings["empty_native"]["median"]
    return {
        "python_over_native": round(py / max(native, 1e-9), 2),
        "above_floor_python_over_native": round((py - floor_py) / max(native - floor_native, 1e-9), 2),
    }
