"""The paper's comparison: every visibility mode on every benchmark scene (section 6).

Figure 12 (visibility along time, and its median and quartiles per method), Figure 13 (camera
speed along time, speed and acceleration distributions per method) and Table 3 (time per
pipeline stage) are reproduced per scene as one figure and two tables. The paper's methods are
RAYCAST (R: rays cast to the sample points at the search stage), NO_ANTICIPATION (W: maps without
the uncertainty blur) and ANTICIPATION (A); REACTIVE (the usual game-engine de-occluder) and
FRAMING_ONLY (no visibility at all) are the baselines of DESIGN.md. A mode the server answers
UNIMPLEMENTED for is reported "unavailable" and the suite goes on.

Figure 11 (map resolutions) is one `camdirector eval --scenario F --visibility ANTICIPATION
--map-resolution N` run per resolution (Style.map_resolution); the suite runs every scene, the
stress scenes included, at the default 64x64.
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from camdirector.deploy.server_process import ServerProcess
from camdirector.evaluation.scenario import Scenario
from camdirector.evaluation.scenario_file import load_scenario, shipped_scenarios
from camdirector.evaluation.toric.measure import VisibilityMeter
from camdirector.evaluation.toric.run import RunResult, open_channel, plot_run, pyplot_agg, run_on_channel, write_json
from camdirector.pipeline.stages import Stage
from camdirector.pipeline.style import VisibilityMode

PAPER_SCENES = ("stress_medium", "stress_large", "columns_gate", "forest", "forest_corridor")
PAPER_METHODS = (VisibilityMode.RAYCAST, VisibilityMode.NO_ANTICIPATION, VisibilityMode.ANTICIPATION)  # R, W, A
# Every mode the style knows, so a new one is measured without a list to keep: the paper's methods
# in its order, then the others (the baselines) in the enum's.
MODES = tuple(
    m.name
    for m in (*PAPER_METHODS, *(m for m in VisibilityMode if m not in PAPER_METHODS and m is not VisibilityMode.UNSPECIFIED))
)
MODE_LABELS = {"RAYCAST": "R", "NO_ANTICIPATION": "W", "ANTICIPATION": "A", "REACTIVE": "reactive", "FRAMING_ONLY": "framing"}


def suite_scenarios(name: str) -> list[Path]:
    """ "paper": the paper's benchmark scenes; "all": every shipped scenario."""
    shipped = shipped_scenarios()
    if name == "paper":
        return [shipped[s] for s in PAPER_SCENES]
    if name == "all":
        return list(shipped.values())
    raise ValueError(f"unknown suite {name!r}; expected 'paper' or 'all'")


@dataclass(eq=False)
class SuiteResult:
    results: list[RunResult]

    def as_dict(self) -> dict:
        return {"runs": [r.as_dict(series=False) for r in self.results]}

    def table(self) -> str:
        """Figures 12-13 as numbers: median [q1, q3] of visibility, its mean and the share of frames
        not fully visible (occl), which tell runs apart when most frames are fully visible, the mean
        of the paper's rays-only measure (los),
        the median composition error (comp, normalised screen units) and distance to A (m), speed
        and acceleration per run."""
        head = (
            f"{'scene':<17} {'mode':<16} {'status':<6} {'visibility med [q1 q3]':<23} {'mean':>5} {'occl':>5} {'los':>5} "
            f"{'comp':>5} {'distA':>5} {'speed m/s med [q1 q3]':<23} {'accel m/s2 med [q1 q3]':<24} {'cuts':>4} "
            f"{'compute ms p50/p99':>19}"
        )
        lines = [head, "-" * len(head)]
        for r in self.results:
            row = f"{r.scenario.name:<17} {r.mode:<16} {r.status:<6} "
            if r.measurement is None:
                lines.append(row + (r.message if r.status != "unavailable" else ""))
                continue
            s = r.measurement.summary()
            c = s["compute_ms"]
            row += (
                f"{_quartiles(s['visibility']):<23} {_num(s['visibility']['mean']):>5} {_num(s['occluded_share']):>5} "
                f"{_num(s['line_of_sight']['mean']):>5} {_num(s['composition_error']['median']):>5} "
                f"{_num(s['distance_to_a_m']['median'], 1):>5} {_quartiles(s['speed_m_s']):<23} "
                f"{_quartiles(s['accel_m_s2']):<24} {s['cuts']:>4} {_num(c['p50']):>9}/{_num(c['p99']):<9}"
            )
            if r.status != "ok":
                row += f"  ({r.status}: {r.message})"
            lines.append(row)
        return "\n".join(lines)

    def stage_table(self) -> str:
        """Table 3 analogue: median server time per pipeline stage, ms."""
        measured = [(r, r.measurement) for r in self.results if r.measurement is not None]
        pipeline = [s.name.lower() for s in Stage]
        stages = sorted(
            {k for _, m in measured for k in m.track.stage_ms},
            key=lambda k: (pipeline.index(k) if k in pipeline else len(pipeline), k),
        )
        head = f"{'scene':<17} {'mode':<16} " + " ".join(f"{k:>12}" for k in stages) + f" {'compute':>9}"
        lines = [head, "-" * len(head)]
        for r, m in measured:
            s = m.summary()
            cells = " ".join(f"{_num(s['stage_ms_median'].get(k), 3):>12}" for k in stages)
            lines.append(f"{r.scenario.name:<17} {r.mode:<16} {cells} {_num(s['compute_ms']['p50'], 3):>9}")
        return "\n".join(lines)


def _num(x, digits: int = 2) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.{digits}f}"


def _quartiles(s: dict) -> str:
    return f"{_num(s['median'])} [{_num(s['q1'])} {_num(s['q3'])}]"


def run_suite(
    scenarios: Sequence[Path | Scenario],
    modes: tuple[str, ...] | list[str] = MODES,
    *,
    out_dir: Path | str | None = None,
    server: str | None = None,
    duration_s: float | None = None,
    plots: bool = True,
    progress: Callable[[str], None] | None = None,
) -> SuiteResult:
    """Runs every mode on every scenario (one session each, in turn) on the server at `server`, or
    on a server subprocess started for the suite. With out_dir: writes runs/<scene>__<mode>.json
    (series included), suite.json, table.txt and, with plots, one figure per scene and per run."""
    if server is None:
        with ServerProcess("--workers", "0", transports=("grpc",)) as proc:
            return run_suite(
                scenarios, modes, out_dir=out_dir, server=proc.grpc, duration_s=duration_s, plots=plots, progress=progress
            )
    out = Path(out_dir) if out_dir is not None else None
    results: list[RunResult] = []
    with open_channel(server) as channel:
        for item in scenarios:
            scenario = item if isinstance(item, Scenario) else load_scenario(item)
            meter = VisibilityMeter(scenario)
            scene_results = []
            for mode in modes:
                result = run_on_channel(channel, scenario, mode, duration_s=duration_s, meter=meter)
                result.server = server
                scene_results.append(result)
                if progress:
                    progress(_progress_line(result))
                if out is not None:
                    if result.measurement is not None:
                        write_json(result, out / "runs" / f"{scenario.name}__{mode}.json")
                        if plots:
                            plot_run(result, out / "runs" / f"{scenario.name}__{mode}.png")
            if out is not None and plots:
                plot_scene_comparison(scene_results, out / f"{scenario.name}.png")
            results.extend(scene_results)
    suite = SuiteResult(results)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "suite.json").write_text(json.dumps(suite.as_dict(), indent=1) + "\n")
        (out / "table.txt").write_text(suite.table() + "\n\n" + suite.stage_table() + "\n")
    return suite


def _progress_line(r: RunResult) -> str:
    if r.measurement is None:
        return f"{r.scenario.name} {r.mode}: {r.status} {r.message}"
    s = r.measurement.summary()
    return (
        f"{r.scenario.name} {r.mode}: {r.status}, {s['frames']} frames in {r.wall_s:.1f} s, "
        f"visibility median {_num(s['visibility']['median'])}"
    )


def plot_scene_comparison(results: list[RunResult], path: Path | str) -> None:
    """Figures 12 and 13 for one scene: visibility and speed along time per mode, and box plots
    (median, quartiles, outliers) of visibility, speed and acceleration per mode."""
    measured = [(r, r.measurement) for r in results if r.measurement is not None]
    if not measured:
        return
    plt = pyplot_agg()
    fig = plt.figure(figsize=(16, 8), layout="constrained")
    grid = fig.add_gridspec(2, 4)
    ax_vis_t, ax_vis_box = fig.add_subplot(grid[0, :3]), fig.add_subplot(grid[0, 3])
    ax_speed_t, ax_speed_box, ax_accel_box = (
        fig.add_subplot(grid[1, :2]),
        fig.add_subplot(grid[1, 2]),
        fig.add_subplot(grid[1, 3]),
    )
    labels = [MODE_LABELS.get(r.mode, r.mode) for r, _ in measured]
    for (_, m), label in zip(measured, labels):
        ax_vis_t.plot(m.track.time_s, m.visibility, lw=0.9, label=label)
        ax_speed_t.plot(m.track.time_s, m.speed_m_s, lw=0.9, label=label)
    ax_vis_t.set_ylabel("visibility")
    ax_vis_t.set_ylim(-0.05, 1.05)
    ax_vis_t.legend(loc="lower left", fontsize=8)
    ax_speed_t.set_ylabel("camera speed, m/s")
    ax_speed_t.set_xlabel("time, s")
    red = {"color": "r"}
    for ax, series, title in (
        (ax_vis_box, "visibility", "visibility"),
        (ax_speed_box, "speed_m_s", "speed, m/s"),
        (ax_accel_box, "accel_m_s2", "acceleration, m/s^2"),
    ):
        ax.boxplot(
            [_finite(getattr(m, series)) for _, m in measured],
            tick_labels=labels,
            medianprops=red,
            flierprops={"marker": "+", "markeredgecolor": "r", "markersize": 3},
        )
        ax.set_title(title, fontsize=9)
    ax_vis_box.set_ylim(-0.05, 1.05)
    unavailable = [r.mode for r in results if r.status == "unavailable"]
    title = f"{measured[0][0].scenario.name}: " + ", ".join(f"{label} = {r.mode}" for (r, _), label in zip(measured, labels))
    if unavailable:
        title += f"   (unavailable: {', '.join(unavailable)})"
    fig.suptitle(title, fontsize=10)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _finite(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    return x[np.isfinite(x)]


def print_progress(line: str) -> None:
    print(line, file=sys.stderr, flush=True)
