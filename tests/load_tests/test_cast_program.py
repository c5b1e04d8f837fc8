"""load_tests/cast_program.py judges a cast's eval-match result by issue 41's program bars: each bar
met on figures inside its limit, and each failing alone on its figure past it; a match's result
through eval-match (load_tests/program_phases.py) by the same bars, its shots on the match's clock;
a server's floor is measured on a real server. (The cast itself, a
real-time run of minutes, is not run here: tests/bridges/test_program_record.py runs a cast into
eval-match end to end.)"""

from __future__ import annotations

import copy

import pytest

from camdirector.deploy.server_process import ServerProcess
from load_tests.cast_program import bars, compute_floor

AGAINST = {"kills": 30, "greedy_2s_kill_coverage": 0.643, "first_person": {"hltv": 0.214, "autotrack": 0.286}}


def _result() -> dict:
    """An eval-match --program result (its keys as eval-match writes them) inside every bar."""
    figures = {
        "kill_coverage_first_person": 0.633,
        "program_visibility": 0.912,
        "shown_height": {"median": 0.2958, "max": 0.567, "over_60pc": 0.0},
        "nobody_shown": {"overview": 0.0048, "other": 0.0199},
        "shots": {"median": 3.0, "under_2s": 0},
        "long_shots_missing_kills": 0,
        "replays": {"kills_with_room": 11, "kills_with_room_replayed": 7, "live_kills_missed_for_replay": 0},
        "places": {"program": {"outside": 0, "solid": 0, "swept_through_walls": 0}},
        "compute_ms": {"median": 1.057, "p99": 1.897},
    }
    return {"program": {"director": "planned", "shots_on_air": {"under_2s": 0}}, "directors": {"planned": figures}}


PLACES = "program poses outside, in solid, swept through walls"
BOUND, BETTER = "kill coverage (first person) over the greedy 2-s bound", "kill coverage (first person) over the better baseline"
# (bar, the figure's path in the result, a value past the bar)
PAST = [
    ("frames of nobody outside overviews", ("directors", "planned", "nobody_shown", "other"), 0.0201),
    ("frames with a player over 0.6 of the height", ("directors", "planned", "shown_height", "over_60pc"), 0.0002),
    ("median shown height", ("directors", "planned", "shown_height", "median"), 0.149),
    ("program visibility", ("directors", "planned", "program_visibility"), 0.849),
    ("median shot, s", ("directors", "planned", "shots", "median"), 2.97),
    ("median shot, s", ("directors", "planned", "shots", "median"), 8.1),
    ("shots under 2 s (match clock, on air)", ("directors", "planned", "shots", "under_2s"), 1),
    ("shots under 2 s (match clock, on air)", ("program", "shots_on_air", "under_2s"), 1),
    ("shots over 20 s while a kill happens outside", ("directors", "planned", "long_shots_missing_kills"), 1),
    ("kills with room replayed", ("directors", "planned", "replays", "kills_with_room_replayed"), 5),
    ("live kills missed for a replay", ("directors", "planned", "replays", "live_kills_missed_for_replay"), 1),
    (PLACES, ("directors", "planned", "places", "program", "solid"), 1),
    (PLACES, ("directors", "planned", "places", "program", "swept_through_walls"), 2),
    ("compute p99, ms", ("directors", "planned", "compute_ms", "p99"), 5.01),
    (BOUND, ("directors", "planned", "kill_coverage_first_person"), 0.54),  # 0.85 * 0.643 = 0.547
]


def test_a_program_inside_every_bar_meets_them_all():
    checked = bars(_result(), AGAINST)
    assert all(b["met"] for b in checked), [b for b in checked if not b["met"]]
    assert len(checked) == 13
    # without the baselines, the two kill coverage bars are left out
    assert [b["bar"] for b in bars(_result(), None)] == [b["bar"] for b in checked[:-2]]


@pytest.mark.parametrize("bar, path, value", PAST)
def test_a_figure_past_its_bar_fails_that_bar_alone(bar, path, value):
    result = copy.deepcopy(_result())
    node = result
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    assert [b["bar"] for b in bars(result, AGAINST) if not b["met"]] == [bar]


def test_kill_coverage_under_the_better_baseline_fails_that_bar():
    against = {**AGAINST, "first_person": {"hltv": 0.214, "autotrack": 0.5}}  # 0.633 < 0.5 + 0.15
    assert [b["bar"] for b in bars(_result(), against) if not b["met"]] == [BETTER]


def test_a_result_of_a_match_through_eval_match_is_judged_on_its_directors_figures_alone():
    """No `program` in it (eval-match of a match file, not of a recorded program): the director
    named, the shots under 2 s on the match's clock only."""
    result = copy.deepcopy(_result())
    del result["program"]
    checked = bars(result, AGAINST, "planned")
    assert all(b["met"] for b in checked) and len(checked) == 13
    assert [b["value"] for b in checked if b["bar"] == "shots under 2 s"] == [[0]]
    result["directors"]["planned"]["shots"]["under_2s"] = 2
    assert [b["bar"] for b in bars(result, AGAINST, "planned") if not b["met"]] == ["shots under 2 s"]
    with pytest.raises(KeyError):
        bars(result, AGAINST, "hltv")  # a director the result does not hold


def test_the_floor_is_the_servers_own_compute_of_framing_only_frames_and_a_health_check(tmp_path):
    """A real server's floor: the frames asked for, each figure a positive time, the p99 not under
    the median."""
    with ServerProcess("--workers", "1", "--data-dir", str(tmp_path), transports=("grpc",)) as server:
        assert server.grpc is not None
        floor = compute_floor(server.grpc, frames=40)
    assert floor["frames"] == 40
    assert 0.0 < floor["compute_ms"]["median"] <= floor["compute_ms"]["p99"]
    assert floor["health_rtt_ms_median"] > 0.0
