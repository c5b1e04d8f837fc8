"""`camdirector eval-match` end to end: a 20-second bot match on the tiny walled arena of
test_sim.py, added to a registry by the CLI, streamed through a real server for both directors."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from camdirector.evaluation.match.match_file import save_match
from camdirector.evaluation.match.sim import simulate_match
from camdirector.precompute.tracks.registry import LevelRegistry
from tests.evaluation.match.test_sim import arena
from tests.service.tracks_sessions import ROOT, cli_add_level, obj_text

DIRECTOR_FIGURES = {
    "kill_coverage",
    "kill_coverage_first_person",
    "kills",
    "kills_covered",
    "lead_s",
    "shots",
    "short_shots",
    "nobody_runs",
    "cuts_per_min",
    "jump_cuts",
    "framed_visibility",
    "program_visibility",
    "first_person_share",
    "shown_height",
    "long_shots_missing_kills",
    "replays",
    "program_sha256",
    "compute_ms",
    "program_moments",
    "program_s",
    "buffering_replies",
}


@pytest.fixture(scope="module")
def registry(tmp_path_factory):
    folder = tmp_path_factory.mktemp("eval-match")
    (folder / "arena.obj").write_text(obj_text(arena()))
    cli_add_level(folder / "data", "arena", folder / "arena.obj")
    return folder


def arena_match(folder, seed: int):
    """A 20-second match of 6 bots on the arena, written to folder/m<seed>.npz."""
    match = simulate_match(LevelRegistry(folder / "data").load("arena"), "arena", 6, 20.0, np.random.default_rng(seed), seed)
    save_match(match, folder / f"m{seed}.npz")
    return match


# kills, and our director's program through a killer's eyes for some of it (0.26) and Toric
# elsewhere; seed 1's only shot through eyes was of an objective taken alone, now its Toric camera
# (first_person.py)
MATCH_SEED = 4


@pytest.fixture(scope="module")
def registry_and_match(registry):
    return registry, arena_match(registry, MATCH_SEED)


def eval_match(folder, *args: str, seed: int = MATCH_SEED) -> subprocess.CompletedProcess:
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "camdirector.__main__",
            "eval-match",
            str(folder / f"m{seed}.npz"),
            "--data-dir",
            str(folder / "data"),
            *args,
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )


def test_eval_match_reports_every_figure_for_both_directors(registry_and_match):
    folder, match = registry_and_match
    kills = sum(e.kind == "kill" for e in match.events)
    assert kills >= 1, "the seed must give the arena a kill to cover"
    done = eval_match(folder, "--delay", "2", "--json", str(folder / "r.json"), "--plot", str(folder / "r.png"))
    assert done.returncode == 0, done.stderr
    result = json.loads((folder / "r.json").read_text())
    assert result == json.loads(done.stdout)
    assert result["match"]["level"] == "arena" and result["match"]["kills"] == kills
    assert result["delay_s"] == 2.0 and result["rate_hz"] == pytest.approx(30.0)
    assert result["frames_sent"] == 20 * 30 + 61  # the match at 30 Hz, then 2 s and one frame more of its end
    assert set(result["directors"]) == {"planned", "hltv", "autotrack"}
    ceilings = result["ceilings"]
    assert ceilings["kills"] == kills and 0.0 <= ceilings["greedy_2s_kill_coverage"] <= ceilings["reference_kill_coverage"]
    # the autotrack looks through its living player's eyes (from a corpse's, 8 units up, the measure
    # sees no eyes); the others never do
    assert result["directors"]["autotrack"]["first_person_share"] > 0.5
    # ours looks through a player's eyes for some shots (first_person.py) and frames players in others
    assert 0.0 < result["directors"]["planned"]["first_person_share"] < 1.0
    assert result["directors"]["planned"]["shown_height"]["median_third_person"] is not None
    for name, figures in result["directors"].items():
        assert DIRECTOR_FIGURES <= set(figures), name
        assert figures["kills"] == kills and 0.0 <= figures["kill_coverage"] <= 1.0
        assert figures["kills_covered"] == figures["lead_s"]["count"] == len(figures["lead_s"]["values"])
        assert figures["buffering_replies"] == 2 * 30  # the first 2 s of game answer no program
        assert figures["program_s"] == pytest.approx(20.0, abs=0.05), "the program reaches the match's end"
        assert figures["shots"]["count"] == len(figures["shots"]["values"]) >= 1
        assert len(figures["short_shots"]) == figures["shots"]["under_2s"]
        nobody = sum(run["moments"] for run in figures["nobody_runs"]) / figures["program_moments"]
        assert nobody == pytest.approx(figures["nobody_shown"]["other"], abs=1e-4)
        assert figures["jump_cuts"] >= 0 and figures["cuts_per_min"] > 0
        assert 0.0 < figures["framed_visibility"] <= 1.0 and 0.0 < figures["program_visibility"] <= 1.0
        assert figures["kill_coverage"] <= figures["kill_coverage_first_person"]
        assert 0.0 < figures["shown_height"]["median"] <= 1.0 and len(figures["program_sha256"]) == 64
        assert figures["compute_ms"]["median"] > 0 and figures["compute_ms"]["n"] == figures["program_moments"]
    assert result["tracks_reference"]["compute_ms"]["n"] == result["frames_sent"]
    for name, ratio in result["compute_ratio_to_tracks"].items():
        expected = result["directors"][name]["compute_ms"]["median"] / result["tracks_reference"]["compute_ms"]["median"]
        assert ratio == pytest.approx(expected, abs=0.01)
    assert result["coverage_gain_over_hltv"] == pytest.approx(
        result["directors"]["planned"]["kill_coverage"] - result["directors"]["hltv"]["kill_coverage"], abs=1e-3
    )
    assert (folder / "r.png").stat().st_size > 10_000


def test_paced_streaming_sends_in_real_time_and_gives_the_same_program(registry_and_match):
    """--paced sends the frames at the game's rate, as a live game would (issue 41's table): the
    stream lasts the match's time, and the program is the one sent as fast as the server answers."""
    folder, _ = registry_and_match
    runs = {}
    for how in ("paced", "unpaced"):
        out = folder / f"{how}.json"
        flags = ["--paced"] if how == "paced" else []
        done = eval_match(folder, "--delay", "2", "--director", "planned", "--minutes", "0.15", *flags, "--json", str(out))
        assert done.returncode == 0, done.stderr
        runs[how] = json.loads(out.read_text())
    assert runs["paced"]["paced"] is True and runs["unpaced"]["paced"] is False
    paced, unpaced = runs["paced"]["directors"]["planned"], runs["unpaced"]["directors"]["planned"]
    match_s = runs["paced"]["frames_sent"] / 30.0
    assert paced["stream_wall_s"] >= match_s - 0.2, "paced: no faster than the game"
    assert paced["program_sha256"] == unpaced["program_sha256"]


def test_video_of_the_program_or_a_clean_skip(registry_and_match):
    folder, _ = registry_and_match
    done = eval_match(
        folder,
        "--delay",
        "0",
        "--minutes",
        "0.2",
        "--json",
        str(folder / "v.json"),
        "--video",
        str(folder / "v.mp4"),
        "--video-seconds",
        "2",
    )
    assert done.returncode == 0, done.stderr
    video = json.loads((folder / "v.json").read_text())["video"]
    if "skipped" in video:  # no EGL here: said, and the run still succeeds
        assert "no video" in done.stderr
        return
    assert video["frames"] >= 55 and video["size_px"] == [480, 270] and (folder / "v.mp4").stat().st_size > 1000


def test_bad_arguments_and_unknown_level_exit_2(registry_and_match, tmp_path):
    folder, match = registry_and_match
    done = eval_match(folder, "--delay", "301", "--json", str(tmp_path / "x.json"))
    assert done.returncode == 2 and "--delay" in done.stderr
    other = tmp_path / "empty-registry"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "camdirector.__main__",
            "eval-match",
            str(folder / f"m{MATCH_SEED}.npz"),
            "--delay",
            "0",
            "--json",
            str(tmp_path / "x.json"),
            "--data-dir",
            str(other),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert done.returncode == 2 and "no level named 'arena'" in done.stderr
    assert not (tmp_path / "x.json").exists()


def test_a_match_whose_players_respawn_near_where_they_fell_streams_through(registry):
    arena_match(registry, 3)
    done = eval_match(registry, "--delay", "2", "--json", str(registry / "r3.json"), seed=3)
    assert done.returncode == 0, done.stderr


def _figures(kills: int, coverage: float) -> dict:
    """The figures plot_result reads, for a director that measured `kills` kills."""
    return {"kills": kills, "kill_coverage": coverage, "lead_s": {"values": [1.0]}, "shots": {"values": [3.0], "median": 3.0}}


@pytest.mark.parametrize(
    "measured, title",
    [
        ({"planned": 35, "hltv": 35}, "arena, delay 10 s, 35 kills measured (41 in the match)"),
        ({"planned": 35, "hltv": 34}, "arena, delay 10 s, kills measured: planned 35, hltv 34 (41 in the match)"),
    ],
)
def test_the_plots_title_counts_the_kills_measured(tmp_path, monkeypatch, measured, title):
    """The match's kills include suicides and deaths to the world, which no director can cover
    and kill coverage leaves out (measure.py): the title counts what the bars measure."""
    from matplotlib.figure import Figure

    from camdirector.evaluation.match.evaluate import plot_result

    saved = []
    monkeypatch.setattr(Figure, "savefig", lambda figure, *args, **kwargs: saved.append(figure))
    result = {
        "match": {"level": "arena", "kills": 41},
        "delay_s": 10.0,
        "directors": {name: _figures(kills, 0.5) for name, kills in measured.items()},
    }
    plot_result(result, tmp_path / "r.png")
    [figure] = saved
    assert figure.axes[0].get_title() == title
