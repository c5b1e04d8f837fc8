"""The Toric math's micro-benchmark (load_tests/toric_native.py): every case on both sides with its
floor. A tiny run; no timing is asserted."""

from __future__ import annotations

import json

from load_tests import toric_native


def test_the_benchmark_reports_every_case_on_both_sides_with_its_floor(tmp_path):
    """load_tests/toric_native.py runs and reports what its docstring promises (a tiny run, no timing asserted)."""
    out = tmp_path / "out.json"
    assert toric_native.main(["--blocks", "3", "--calls", "2", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    cases = ("make_torus", "torus_position_1", f"torus_position_{toric_native.PLACES}", "compose_pose")
    assert set(result["per_call_us"]) == {f"{c}_{side}" for c in (*cases, "empty") for side in ("python", "native")}
    assert set(result["speedup"]) == set(cases)
    assert all(s["n"] == 3 and 0.0 < s["median"] <= s["p99"] for s in result["per_call_us"].values())
