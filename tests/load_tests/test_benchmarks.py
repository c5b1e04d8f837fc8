"""The benchmarks run and report what their docstrings promise (tiny runs; they assert no timing)."""

from __future__ import annotations

import asyncio
import json

import pytest

from camdirector.deploy.server_process import ServerProcess
from load_tests import (
    capacity,
    dashboard_bench,
    monitors_bench,
    movers_bench,
    oversize,
    overview_bench,
    real_matches,
    soak,
    stream,
    tracks_bench,
)


def _run(main, tmp_path, *args) -> dict:
    out = tmp_path / "out.json"
    assert main([*args, "--json", str(out)]) == 0
    return json.loads(out.read_text())


@pytest.mark.shared_data
def test_overview_bench_reports_end_to_end_against_planning(shared_data, tmp_path):
    result = _run(
        overview_bench.main,
        tmp_path,
        "--data-dir",
        str(shared_data),
        "--clips",
        "bandai_run_30fps",
        "--frames",
        "40",
        "--reps",
        "1",
    )
    clip = result["clips"]["bandai_run_30fps"]
    assert clip["frames"] == 40 and clip["end_to_end_s"]["n"] == 1
    # Both measured, never compared: two runs of a shared machine's seconds (end to end includes
    # the planning, but a burst of load on one run can make it the shorter).
    assert clip["end_to_end_s"]["median"] > 0.0 and clip["planning_only_s"]["median"] > 0.0
    assert {"preview_video", "annealing_and_shots", "job_process_total"} <= set(clip["job_stage_ms_median"])


@pytest.mark.shared_data
def test_tracks_bench_reports_a_level_and_its_routes(shared_data, tmp_path):
    # --no-prm: the comparison with PRMs (compare_with_prm, 35 s of the 60) is tested on its own in
    # tests/precompute/tracks/test_tracks_real_levels.py; this checks the benchmark's report
    result = _run(tracks_bench.main, tmp_path, "--data-dir", str(shared_data), "--levels", "dungeon", "--no-prm")
    level = result["levels"]["dungeon"]
    assert level["precompute_s"] > 0.0 and level["artifact_load_ms"] > 0.0
    assert level["nodes"] > 0 and level["edges"] > 0 and "prm_compared" not in level
    assert set(level["stage_ms"]) >= {"skeleton", "clustering", "graph", "visibility"}
    routes = level["routes"]
    assert set(routes) == {"default", "tightest", "open"}
    assert routes["tightest"]["half_width_m"] < routes["open"]["half_width_m"]
    for route in routes.values():
        assert set(route["shot_sizes"]) == {"medium", "long", "extreme_long"} and route["length_m"] > 0.0
        for run in route["shot_sizes"].values():
            assert run["frames"] > 0 and 0.0 <= run["visible"] <= run["line_of_sight"] <= 1.0
            assert 0.0 <= run["framed_in_frame"] <= 1.0 and run["cuts_per_min"] >= 0.0


def test_stream_bench_reports_round_trips(tmp_path):
    result = _run(stream.main, tmp_path, "--transport", "zmq", "--sessions", "1", "--seconds", "1")
    assert result["dropped_frames"] == 0 and not result["errors"]


@pytest.mark.parametrize("transport", ["grpc", "zmq"])
def test_a_stream_run_closes_its_sessions(transport):
    # a server with room for 2: the second run opens its sessions only where the first closed its
    # own (the server's reclaim window, 60 s by default, would otherwise still hold them)
    with ServerProcess("--workers", "1", "--max-sessions", "2") as server:
        address = server.grpc if transport == "grpc" else server.zmq
        for _ in range(2):
            result = asyncio.run(stream.run(transport, address, 2, 60.0, 0.2))
            assert result["dropped_frames"] == 0 and not result["errors"]


def test_capacity_reports_the_last_count_that_held_with_its_floor_and_load_generator(tmp_path):
    result = _run(
        capacity.main,
        tmp_path,
        "--modes",
        "FRAMING_ONLY",
        "--transports",
        "zmq",
        "--max-sessions",
        "2",
        "--seconds",
        "0.5",
        "--warmup-frames",
        "2",
        "--settle-s",
        "0",
        "--workers",
        "1",
        "--generator",
        "python",  # the compiled driver's run: tests/load_tests/test_native_generator.py
    )
    (case,) = result["cases"]
    assert (case["mode"], case["transport"], case["server_workers"]) == ("FRAMING_ONLY", "zmq", 1)
    assert result["counts_tried_up_to"] == [1, 2] and result["server"]["checkout"]
    passed = [s["sessions"] for s in case["steps"] if s["passed"]]
    assert case["capacity_sessions"] == result["capacity_sessions"]["FRAMING_ONLY"]["zmq"] == max(passed, default=0)
    for step in case["steps"]:  # each verdict is the rule applied to the step's own numbers
        assert step["passed"] == (
            step["rtt_ms"]["p99"] <= 10.0 and step["late_frames"] == step["dropped_frames"] == 0 and not step["errors"]
        )
        assert step["floor_rtt_ms"]["p50"] > 0 and step["client_cpu_fraction_of_core"] > 0
        assert step["frames_sent"] == step["sessions"] * 30
        # where a frame's CPU goes: the front and the one worker both worked, and so did the generator
        assert min(step["cpu_us_per_frame"][k] for k in ("front", "workers", "load_generator")) > 0


@pytest.mark.parametrize(
    "max_sessions, counts",
    [
        (1, [1]),
        (2, [1, 2]),
        (20, [1, 2, 4, 8, 16, 20]),
        (40, [1, 2, 4, 8, 16, 24, 32, 40]),
    ],
)
def test_capacity_tries_counts_doubling_then_by_eight(max_sessions, counts):
    assert capacity.session_counts(max_sessions) == counts


@pytest.mark.parametrize(
    "holds, counts, tried, found",
    [
        (0, [1, 2], [1], 0),
        (2, [1, 2], [1, 2], 2),
        (19, [1, 2, 4, 8, 16, 24], [1, 2, 4, 8, 16, 24, 20, 18, 19], 19),
        (21, [1, 2, 4, 8, 16, 24], [1, 2, 4, 8, 16, 24, 20, 22, 21], 21),
        (40, [1, 2, 4, 8, 16, 24, 32, 40], [1, 2, 4, 8, 16, 24, 32, 40], 40),
    ],
)
def test_capacity_halves_the_gap_after_the_first_count_that_fails(holds, counts, tried, found):
    asked = []

    def passes(n: int) -> bool:
        asked.append(n)
        return n <= holds

    assert capacity.largest_passing(counts, passes) == found and asked == tried


def test_dashboard_bench_reports_watched_against_alone(tmp_path):
    result = _run(dashboard_bench.main, tmp_path, "--sessions", "1", "--seconds", "1", "--workers", "1")
    assert result["alone"]["dropped_frames"] == result["watched"]["dropped_frames"] == 0
    assert result["watched"]["detail_requests"] >= 1 and set(result["rtt_ratio_watched_vs_alone"]) == {"p50", "p99"}


def test_monitors_bench_reports_render_cost_and_watched_against_unwatched(tmp_path):
    result = _run(
        monitors_bench.main, tmp_path, "--sessions", "1", "--seconds", "1", "--workers", "1", "--renders", "3", "--rounds", "1"
    )
    (round_,) = result["rounds"]
    assert round_["unwatched"]["dropped_frames"] == round_["watched"]["dropped_frames"] == 0
    watched = round_["watched"]
    assert watched["monitors"] == watched["server_view_streams"] == 1 and not watched["monitor_errors"]
    assert watched["monitor_parts_min"] >= 1 and watched["view_renders"] >= 1
    assert set(result["rtt_ratio_watched_vs_unwatched"]) == {"p50", "p99"}
    assert round_["unwatched"]["baseline_rtt_ms"]["p50"] > 0 and watched["baseline_rtt_ms"]["p50"] > 0
    render = result["render"]
    assert render["picture_px"] == [320, 180] and render["placeholders"] == 0
    assert render["frames_shown"] == render["render_ms"]["n"] == 3, "each ask is a render of its own frame"
    assert render["render_ms"]["median"] > 0 and render["image_bytes"]["median"] > 0


def test_soak_reports_memory_and_descriptors_over_every_kind_of_session(tmp_path):
    result = _run(
        soak.main, tmp_path, "--minutes", "0.05", "--warmup-s", "2", "--sample-s", "0.5", "--workers", "1", "--frames", "5"
    )
    assert result["error_count"] == 0 and not result["worker_restarted"]
    assert set(result["sessions"]) == {c.name for c in soak.combinations()} and min(result["sessions"].values()) >= 1
    assert result["samples"] >= 3 and len(result["workers"]) == 1 and result["rss_slope_mb_per_min"] is not None
    assert result["workers"][0]["open_fds"]["start"] > 0 and result["front"]["rss_mb"]["end"] > 0


def test_movers_bench_reports_every_mode_and_count_against_none(tmp_path):
    result = _run(movers_bench.main, tmp_path, "--frames", "20", "--warmup", "5", "--movers", "0,3")
    cases = {(c["mode"], c["movers"]): c for c in result["cases"]}
    assert set(cases) == {(m, n) for m in movers_bench.MODES for n in (0, 3)}
    assert all(c["compute_ms"]["n"] == 20 and "ingest" in c["stage_ms_median"] for c in cases.values())
    assert "projection" in cases[("ANTICIPATION", 3)]["stage_ms_median"]
    assert set(result["median_ratio_to_0_movers"]) == set(movers_bench.MODES)
    assert result["floor_stale_frame_wall_ms"]["median"] > 0 and all(c["median_over_floor"] > 0 for c in cases.values())


def test_movers_bench_runs_the_modes_asked_on_the_frame_path_asked(tmp_path):
    result = _run(
        movers_bench.main, tmp_path, "--frames", "20", "--warmup", "5", "--movers", "3", "--modes", "ANTICIPATION",
        "--frame-path", "compiled",
    )  # fmt: skip
    assert result["frame_path"] == "compiled"
    assert [(c["mode"], c["movers"], c["map_backend"]) for c in result["cases"]] == [("ANTICIPATION", 3, "native")]
    assert movers_bench.main(["--modes", "RAYCAST"]) == 2  # a mode it does not offer


def test_real_matches_report_every_director_beside_the_ceilings_and_the_same_program_twice(tmp_path):
    """A real duel's first 24 s (its first kill at 20 s), run twice from scratch (the level added anew, a new server):
    issue 29's "two runs of the same match give the same program, pose for pose"."""
    result = _run(
        real_matches.main,
        tmp_path,
        "--only",
        "duel_bravado",
        "--minutes",
        "0.4",
        "--rate-hz",
        "15",
        "--twice",
        "--markdown",
        str(tmp_path / "table.md"),
    )
    duel = result["matches"]["duel_bravado"]
    assert set(duel["directors"]) == {"planned", "hltv", "autotrack"} and duel["match"]["players"] == 2
    assert duel["same_program_twice"] == {"planned": True, "hltv": True, "autotrack": True}
    assert duel["ceilings"]["kills"] >= 1
    table = (tmp_path / "table.md").read_text().splitlines()
    assert len(table) == 2 + 4 and table[2].startswith("| duel_bravado | planned |")


def test_real_matches_runs_only_the_directors_named(tmp_path):
    """--directors planned: our director alone (docs/casting.md's before/after tables), the ceilings still beside it."""
    args = ("--only", "duel_bravado", "--minutes", "0.4", "--rate-hz", "15", "--directors", "planned")
    result = _run(real_matches.main, tmp_path, *args)
    duel = result["matches"]["duel_bravado"]
    assert set(duel["directors"]) == {"planned"} and duel["ceilings"]["kills"] >= 1


def test_real_matches_refuses_a_director_it_does_not_know(tmp_path, capsys):
    assert real_matches.main(["--only", "duel_bravado", "--directors", "planned,nobody", "--json", str(tmp_path / "o.json")]) == 2
    assert "unknown director ['nobody']" in capsys.readouterr().err and not (tmp_path / "o.json").exists()


def test_oversize_bench_reports_frames_quiet_and_attacked_and_every_attack_answered(tmp_path):
    result = _run(oversize.main, tmp_path, "--sessions", "1", "--seconds", "1", "--workers", "1", "--oversize-mib", "6")
    assert result["quiet"]["dropped_frames"] == result["attacked"]["dropped_frames"] == 0
    assert set(result["rtt_ratio_attacked_vs_quiet"]) == {"p50", "p99", "max"}
    attacks = result["attacks"]
    assert set(attacks) == {"http_login", "http_login_chunked", "http_upload_without_key", "zmq_without_key"}
    assert all(attack["sent"] >= 1 for attack in attacks.values())
    assert set(attacks["http_login"]["outcomes"]) <= {"413", "closed"}
    assert set(attacks["http_upload_without_key"]["outcomes"]) <= {"401", "closed"}
    assert set(attacks["zmq_without_key"]["outcomes"]) == {"dropped"}
