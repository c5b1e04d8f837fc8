"""The compiled TORIC rig's benchmark (load_tests/toric_rig_native.py): both sides and their floors,
the speed-up, and how far apart the two sides' poses were. A tiny run; no timing is asserted."""

from __future__ import annotations

import json

from load_tests import toric_rig_native


def test_the_benchmark_reports_both_sides_with_their_floors(tmp_path):
    out = tmp_path / "out.json"
    assert toric_rig_native.main(["--frames", "5", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    measures = ("rig_run", "framing", "motion", "visibility")
    sides = {f"{what}_{side}" for what in (*measures, "empty") for side in ("python", "native")}
    assert set(result["per_frame_us"]) == sides
    assert all(s["n"] == 5 and 0.0 < s["median"] <= s["p99"] for s in result["per_frame_us"].values())
    assert set(result["speedup"]) == set(measures)
    assert all(set(s) == {"python_over_native", "above_floor_python_over_native"} for s in result["speedup"].values())
    assert 0.0 <= result["max_position_diff_m"] <= 1e-9
