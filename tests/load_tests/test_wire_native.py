"""The compiled wire's benchmark (load_tests/wire_native.py): both sides of the decode, the encode
and the sessions' figures, their floors and the speed-ups. A tiny run; no timing is asserted."""

from __future__ import annotations

import json

from load_tests import wire_native


def test_the_benchmark_reports_both_sides_with_their_floors(tmp_path):
    out = tmp_path / "out.json"
    assert wire_native.main(["--frames", "5", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    measures = ("decode", "encode", "compute", "compute_minus_stages", "table_wall")
    sides = {f"{what}_{side}" for what in (*measures, "empty") for side in ("python", "native")}
    assert set(result["per_frame_us"]) == sides
    assert all(s["n"] == 5 and 0.0 < s["median"] <= s["p99"] for s in result["per_frame_us"].values())
    assert set(result["speedup"]) == set(measures)
    assert all(set(s) == {"python_over_native", "above_floor_python_over_native"} for s in result["speedup"].values())
    # load_tests.frame_profile's frame: 965 bytes from frame 128 on, where its number takes two bytes
    assert (result["states_per_frame"], result["request_bytes"]) == (10, 964)
