"""The compiled RayScene twin's benchmark (load_tests/scene_native.py): both sides, their floors and
the ratios. One pass over the walk; no timing is asserted."""

from __future__ import annotations

import json

from load_tests import scene_native


def test_one_pass_reports_both_scenes_their_floors_and_ratios(tmp_path):
    out = tmp_path / "out.json"
    assert scene_native.main(["--passes", "1", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    for side in ("ray_scene", "scene", "visible_share"):
        assert 0.0 < result[side]["median_us"] <= result[side]["p99_us"]
    for floor in ("ray_scene_floor", "scene_floor"):
        assert result[floor]["median_us"] > 0.0
    assert result["ray_scene_over_scene"] > 0.0 and result["calls_each"] > 0 and 0.0 < result["mean_hidden_share"] < 1.0
