"""The FRAMING and MOTION stages' benchmark (load_tests/framing_motion_native.py): both cases, both
sides and their floors. A tiny run; no timing is asserted."""

from __future__ import annotations

import json

from load_tests import framing_motion_native


def test_the_benchmark_reports_both_cases_on_both_sides_with_their_floors(tmp_path):
    out = tmp_path / "out.json"
    assert framing_motion_native.main(["--frames", "5", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert set(result["cases"]) == {"one_target", "two_targets"}
    for case in result["cases"].values():
        sides = {f"{what}_{side}" for what in ("stages", "error", "empty") for side in ("python", "native")}
        assert set(case["per_frame_us"]) == sides
        assert all(s["n"] == 5 and 0.0 < s["median"] <= s["p99"] for s in case["per_frame_us"].values())
        assert set(case["speedup"]) == {"stages", "error"}
