"""load_tests/qtv_bridge.py runs and reports what its docstring promises (a tiny run; no timing asserted)."""

from __future__ import annotations

import json

from load_tests import qtv_bridge


def test_qtv_bridge_reports_the_bridge_against_play_match_and_the_floor(tmp_path):
    out = tmp_path / "out.json"
    assert qtv_bridge.main(["--seconds", "3", "--reps", "1", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["players"] == 4
    local = result["in_process"]
    n = local["frames"]
    assert 90 <= n <= 92  # 3 s at 30 Hz
    for name in ("bridge_frame_us", "decode_offer_us", "sample_build_us", "play_match_frame_us", "floor_frame_us"):
        assert local[name]["n"] == n and local[name]["median"] >= 0.0 and local[name]["mean"] > 0.0
    assert local["bridge_over_play_match"] > 0.0 and local["play_match_over_floor"] > 0.0
    e2e = result["end_to_end"]
    for name in ("bridge_rtt_ms", "play_match_rtt_ms", "floor_rtt_ms"):
        assert e2e[name]["n"] == n and e2e[name]["median"] > 0.0
