"""load_tests/bvh_native.py runs and reports what its docstring promises (a tiny run; no timing is
asserted)."""

from __future__ import annotations

import json

from load_tests import bvh_native


def test_the_quick_run_reports_both_engines_and_their_floors_on_the_demo_scene(tmp_path):
    out = tmp_path / "out.json"
    assert bvh_native.main(["--quick", "--json", str(out)]) == 0
    demo = json.loads(out.read_text())["demo"]
    assert demo["triangles"] > 1000 and set(demo["build_ms"]) == {"bvh", "embree"}
    for query in ("occluded", "first_hit"):
        assert set(demo[query]["floor_us"]) == {"bvh", "embree"}
        for batch in map(str, bvh_native.BATCHES):
            row = demo[query][batch]
            assert row["bvh"]["rays_per_s"] > 0 and row["embree"]["rays_per_s"] > 0 and row["embree_over_bvh"] > 0
