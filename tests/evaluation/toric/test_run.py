"""End to end: scenarios through a real `camdirector serve` session, the CLI, and the suite."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from camdirector.evaluation import cli
from camdirector.evaluation.scenario_file import load_scenario, shipped_scenarios
from camdirector.evaluation.toric.cli import run_eval
from camdirector.evaluation.toric.run import open_channel, run_on_channel
from camdirector.evaluation.toric.suite import run_suite

SHIPPED = shipped_scenarios()


def test_columns_gate_runs_through_a_real_session_and_writes_json(server, tmp_path):
    out = tmp_path / "run.json"
    plot = tmp_path / "run.png"
    rc = cli.main(
        [
            "eval",
            "--scenario",
            str(SHIPPED["columns_gate"]),
            "--visibility",
            "FRAMING_ONLY",
            "--json",
            str(out),
            "--plot",
            str(plot),
            "--server",
            server.grpc,
            "--duration",
            "3",
        ]
    )
    assert rc == 0 and plot.stat().st_size > 10_000
    result = json.loads(out.read_text())
    assert (result["status"], result["mode"], result["scenario"]["name"]) == ("ok", "FRAMING_ONLY", "columns_gate")
    summary, series = result["summary"], result["series"]
    assert summary["frames"] == 181 and series["frame"] == list(range(1, 182))
    assert series["time_s"][-1] == 3.0
    assert 0.0 <= summary["visibility"]["q1"] <= summary["visibility"]["median"] <= summary["visibility"]["q3"] <= 1.0
    assert summary["speed_m_s"]["n"] == 180 and summary["accel_m_s2"]["n"] == 179
    assert summary["cuts"] == 0 and summary["compute_ms"]["p50"] > 0.0
    assert set(summary["stage_ms_median"]) >= {"ingest", "framing", "motion", "visibility"}
    # the rig's own estimate (16 samples) and the measurement (every vertex) agree on this scene
    gap = np.abs(np.array(series["visibility"]) - np.array(series["rig_visibility"]))
    assert gap.mean() < 0.1
    # and the camera keeps up with a walking avatar: no jumps between frames
    cam = np.array(series["camera_position"])
    assert np.linalg.norm(np.diff(cam, axis=0), axis=1).max() < 0.2


def test_stress_scene_with_spawning_cylinders_runs(server):
    scenario = load_scenario(SHIPPED["stress_medium"])
    with open_channel(server.grpc) as channel:
        result = run_on_channel(channel, scenario, "FRAMING_ONLY", duration_s=6.0)
    assert result.status == "ok", result.message
    m = result.measurement
    assert len(m.track) == 361 and m.track.stale == 0
    assert set(m.visibility_per_target) == {"sphere_a", "sphere_b"}
    assert np.all((m.visibility >= 0.0) & (m.visibility <= 1.0))


def test_suite_reports_unimplemented_modes_as_unavailable(server, tmp_path):
    scenario = load_scenario(SHIPPED["forest"])
    suite = run_suite(
        [scenario], ["ANTICIPATION", "FRAMING_ONLY"], out_dir=tmp_path, server=server.grpc, duration_s=1.0, plots=True
    )
    status = {r.mode: r.status for r in suite.results}
    assert status["FRAMING_ONLY"] == "ok" and status["ANTICIPATION"] in ("ok", "unavailable")
    table = suite.table()
    assert "forest" in table and "FRAMING_ONLY" in table
    if status["ANTICIPATION"] == "unavailable":
        assert "unavailable" in table and not (tmp_path / "runs" / "forest__ANTICIPATION.json").exists()
    runs = json.loads((tmp_path / "suite.json").read_text())["runs"]
    assert [r["mode"] for r in runs] == ["ANTICIPATION", "FRAMING_ONLY"]
    assert (tmp_path / "forest.png").exists() and (tmp_path / "runs" / "forest__FRAMING_ONLY.json").exists()
    assert "visibility" in (tmp_path / "table.txt").read_text()


def test_cli_registers_eval_and_refuses_bad_input(tmp_path, capsys):
    parser = argparse.ArgumentParser(prog="camdirector")
    cli.add_parsers(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["eval", "--suite", "paper", "--out", str(tmp_path)])
    assert args.handler is run_eval and args.suite == "paper"
    with pytest.raises(SystemExit):
        parser.parse_args(["eval", "--suite", "paper", "--scenario", "x.json"])  # one or the other
    assert cli.main(["eval", "--scenario", str(tmp_path / "absent.json")]) == 2
    assert "cannot read" in capsys.readouterr().err
    assert cli.main(["eval", "--scenario", str(SHIPPED["forest"]), "--visibility", "XRAY"]) == 2
    assert "unknown visibility mode 'XRAY'" in capsys.readouterr().err
    assert cli.main(["eval", "--suite", "paper"]) == 2  # --out is required
    assert cli.main(["eval", "--suite", "paper", "--out", str(tmp_path), "--modes", "A"]) == 2
