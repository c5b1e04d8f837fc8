"""The compiled frame path (a server's `frame_path`, compiled by default) against the Python one,
the reference: the TORIC rig with FRAMING_ONLY compiled (pipeline/toric/compiled_rig.py) against
ToricRig, and the frame's wire decoded and its reply written in camdirector._native
(worker/codec.py frame_from_wire, camera_update_wire). Whole demo sessions through a SessionTable
on each path answer every frame alike (poses within 1e-9 m and 1e-9 rad; the same flags, cuts,
shots and stale answers; the framing error and the toric place within 1e-9; the same stage laps;
replies with the same fields, their numbers within the same margins), through a frame gap, a frame
sent again, and changes of visibility mode that hand the camera to the Python stages and back; the
suite's TORIC recordings' inputs, each visibility mode, alike on both paths; the compiled path's
replies are the bytes the Python codec writes for the same state; a compiled run repeats bit for
bit, also across a snapshot; and the setting reaches the rig from the command line and the
environment, a bad value refused."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

import camdirector.__main__ as cli
import camdirector.front.main
from camdirector.demo.client import frame_updates, session_request
from camdirector.demo.scene import build_demo_scene
from camdirector.geometry.camera import Lens
from camdirector.pipeline.state import FrameState
from camdirector.pipeline.toric.compiled_rig import CompiledToricRig
from camdirector.pipeline.toric.rig import ToricRig
from camdirector.server_settings import ServerSettings
from camdirector.v1 import director_pb2 as pb
from camdirector.worker import codec
from camdirector.worker.checkpoint_stores import dumps_state, loads_state
from camdirector.worker.recording import read_entries
from camdirector.worker.table import SessionTable

RECORDINGS = Path(__file__).resolve().parents[2] / "data" / "recordings"
TOL = 1e-9  # metres for positions, radians for angles, unit for quaternions and screen errors
# A REACTIVE camera pulled in front of an obstacle stands where a ray hit it: the Python rig's
# RayScene casts in Embree's float32 (its distances within 1e-4 relative: test_scene_native.py),
# the compiled rig's Scene in float64. Given the same hits the two deoccluders agree within 1e-12
# (tests/native/test_deoccluder_native.py); here such frames agree within float32's rounding of a
# hit some metres off.
PULLED_TOL = 1e-5  # m, unit quaternion, screen error, on frames the deoccluder moved ("pulled_in"): 2^-24 of tens of metres
FRAMES = 900  # 15 s of the demo at 60 Hz: the walker passes the moving obstacles
SEEN_TOL = 0.01  # share of the targets' samples (and of frames) a compiled search session may lose
# Demo scenes, besides the seed-7 inputs with a gap, whose search sessions are compared by what
# they show: each session parts from its Python twin at its first near-tie, and the share seen
# then differs by up to 0.07 either way from seed to seed (on this demo, both modes).
SEEN_SEEDS = (1, 2, 3, 4, 5, 6)


@dataclass
class Answer:
    """What one frame answered: the reply's stale mark, the reply as sent and parsed, and when it
    was computed, its state."""

    stale: bool
    cut: bool
    shot_id: int
    state: FrameState | None
    body: bytes
    reply: pb.CameraUpdate


def _inputs(styles: dict[int, int], seed: int = 7, gap: bool = True) -> list[pb.FrameUpdate | pb.UpdateStyleRequest]:
    """The frames of the demo scene of `seed` with a gap (frames 301-330 never sent: half a second
    in one step) and frame 500 sent again after 501 (unless not `gap`), and at frame i the style's
    visibility changed to styles[i]."""
    scene = build_demo_scene(seed=seed, duration_s=FRAMES / 60.0 + 1.0)
    frames = [f for f in frame_updates(scene, FRAMES) if not (gap and 300 < f.frame <= 330)]
    out: list[pb.FrameUpdate | pb.UpdateStyleRequest] = []
    for update in frames:
        update.session_id = "s"
        if update.frame in styles:
            out.append(pb.UpdateStyleRequest(session_id="s", style=pb.Style(visibility=styles[update.frame])))
        out.append(update)
        if gap and update.frame == 501:
            out.append(next(f for f in frames if f.frame == 500))
    return out


def _run(
    frame_path: str,
    inputs,
    tmp_path,
    snapshot_at: int | None = None,
    create: pb.CreateSessionRequest | None = None,
    seed: int = 7,
) -> tuple[list[Answer], SessionTable]:
    """Every answer of a session "s" created by `create` (default: the demo scene of `seed`) fed `inputs`,
    on a table whose clock ticks 1 ms a reading (so the stage laps compare); snapshots every 60
    inputs into tmp_path. With snapshot_at, the session is replaced there by its snapshot
    unpickled (as a restore does)."""
    ticks = itertools.count()
    settings = ServerSettings(data_dir=str(tmp_path / frame_path), frame_path=frame_path)
    table = SessionTable(settings, clock=lambda: next(ticks) * 1e-3)
    if create is None:
        create = session_request(build_demo_scene(seed=seed, duration_s=FRAMES / 60.0 + 1.0), Lens())
    table.create("s", create)
    answers = []
    for msg in inputs:
        if isinstance(msg, pb.UpdateStyleRequest):
            table.update_style(msg)
            continue
        body, _ = table.frame_bytes(msg, msg.SerializeToString())
        reply = pb.CameraUpdate.FromString(body)
        held = table.get("s")
        state = None if reply.stale else held.session.last_state
        answers.append(Answer(reply.stale, reply.cut, reply.shot_id, state, body, reply))
        if msg.frame == snapshot_at:
            objects = held.session.creation_objects()
            held.session = loads_state(dumps_state(held.session, objects), objects)
    return answers, table


def _angle(a: float, b: float) -> float:
    return abs(math.remainder(a - b, math.tau))


def _differences(got: list[Answer], want: list[Answer]) -> dict[str, float]:
    """The largest difference of each compared quantity over the frames; asserts what must be equal."""
    assert len(got) == len(want)
    worst = {"position_m": 0.0, "rotation": 0.0, "theta_phi_rad": 0.0, "framing_error": 0.0, "torus": 0.0}
    worst |= {"pulled_position_m": 0.0, "pulled_rotation": 0.0, "pulled_framing_error": 0.0}
    visibility_frames = 0
    for i, (g, w) in enumerate(zip(got, want)):
        assert (g.stale, g.cut, g.shot_id) == (w.stale, w.cut, w.shot_id), i
        assert (g.state is None) == (w.state is None), i
        pulled = "pulled_in" in w.reply.diagnostics.flags
        _reply_differences(g.reply, w.reply, worst, "pulled_" if pulled else "")
        if g.state is None or w.state is None:
            continue
        gs, ws = g.state, w.state
        assert gs.flags == ws.flags, i
        assert gs.stage_ms == ws.stage_ms, i
        assert gs.pose is not None and ws.pose is not None
        assert gs.pose.vertical_fov_deg == ws.pose.vertical_fov_deg
        key = "pulled_" if pulled else ""
        gap = float(np.abs(gs.pose.position_world - ws.pose.position_world).max())
        worst[f"{key}position_m"] = max(worst[f"{key}position_m"], gap)
        q, r = gs.pose.rotation_xyzw, ws.pose.rotation_xyzw
        worst[f"{key}rotation"] = max(worst[f"{key}rotation"], float(min(np.abs(q - r).max(), np.abs(q + r).max())))
        worst[f"{key}framing_error"] = max(worst[f"{key}framing_error"], abs(gs.framing_error - ws.framing_error))
        visibility_frames += gs.visibility != ws.visibility
        gt, wt = gs.toric, ws.toric
        assert gt is not None and wt is not None and gt.b_is_gaze_point == wt.b_is_gaze_point
        worst["theta_phi_rad"] = max(worst["theta_phi_rad"], abs(gt.theta - wt.theta), _angle(gt.phi, wt.phi))
        assert (gt.torus is None) == (wt.torus is None)
        if gt.torus is not None and wt.torus is not None:
            fields = ("a_world", "b_world", "axis_world", "ref_world", "mid_world")
            gaps = [float(np.abs(getattr(gt.torus, f) - getattr(wt.torus, f)).max()) for f in fields]
            worst["torus"] = max(worst["torus"], abs(gt.torus.alpha - wt.torus.alpha), *gaps)
    assert visibility_frames == 0  # the Scene and Embree agree on every sample segment of these sessions
    return worst


def _reply_differences(got: pb.CameraUpdate, want: pb.CameraUpdate, worst: dict[str, float], key: str = "") -> None:
    """Two replies' largest differences into `worst` (their poses and toric places; the poses
    under `key` + their names); asserts the rest is equal, the stage laps and compute_ms included
    (the tables' clocks tick per reading)."""
    fields = ("frame", "time_s", "cut", "shot_id", "visibility", "compute_ms", "stale", "message", "buffering")
    assert [getattr(got, f) for f in fields] == [getattr(want, f) for f in fields]
    gd, wd = got.diagnostics, want.diagnostics
    assert (list(gd.flags), dict(gd.stage_ms), dict(gd.scores)) == (list(wd.flags), dict(wd.stage_ms), dict(wd.scores))
    assert [m.HasField(f) for m in (got, want) for f in ("pose", "diagnostics", "shot")] == [True, True, False] * 2
    assert not got.candidates and not want.candidates
    gp, wp = got.pose, want.pose
    assert gp.vertical_fov_deg == wp.vertical_fov_deg
    gaps = (abs(getattr(gp.position, a) - getattr(wp.position, a)) for a in "xyz")
    worst[f"{key}position_m"] = max(worst[f"{key}position_m"], *gaps)
    q, r = (np.array([getattr(p.rotation, a) for a in "xyzw"]) for p in (gp, wp))
    worst[f"{key}rotation"] = max(worst[f"{key}rotation"], float(min(np.abs(q - r).max(), np.abs(q + r).max())))
    worst["theta_phi_rad"] = max(worst["theta_phi_rad"], abs(gd.theta - wd.theta), _angle(gd.phi, wd.phi))
    worst["torus"] = max(worst["torus"], abs(gd.alpha - wd.alpha))


def _agree(got: list[Answer], want: list[Answer]) -> None:
    worst = _differences(got, want)
    print(worst)  # pytest -s: the margins
    assert all(value <= (PULLED_TOL if name.startswith("pulled_") else TOL) for name, value in worst.items()), worst


def _same_bits(got: list[Answer], want: list[Answer]) -> None:
    assert not any(_differences(got, want).values())


@pytest.fixture(scope="module")
def framing_only(tmp_path_factory):
    """The python and the compiled answers of a FRAMING_ONLY session, and the compiled table."""
    tmp_path = tmp_path_factory.mktemp("framing_only")
    inputs = _inputs({})
    python, _ = _run("python", inputs, tmp_path)
    compiled, table = _run("compiled", inputs, tmp_path)
    return inputs, python, compiled, table


def test_a_framing_only_session_agrees_frame_by_frame(framing_only):
    _, python, compiled, table = framing_only
    assert isinstance(table.get("s").session.rig, CompiledToricRig)
    assert sum(a.stale for a in compiled) == 1 and sum(a.cut for a in compiled) >= 1
    _agree(compiled, python)


def test_the_compiled_wire_sends_the_python_codecs_bytes(framing_only):
    """Each computed frame's reply is what camera_update_msg writes for its state (map entries by
    key: upb's own order is its hash table's, seeded per process); a frame sent again repeats its
    first answer, marked stale."""
    _, _, compiled, _ = framing_only
    for answer in compiled:
        if answer.state is not None:
            want = codec.camera_update_msg(answer.state, compute_ms=answer.reply.compute_ms)
            assert answer.body == want.SerializeToString(deterministic=True)
    (again,) = [a for a in compiled if a.stale]
    (first,) = [a for a in compiled if a.reply.frame == again.reply.frame and not a.stale]
    repeated = pb.CameraUpdate.FromString(first.body)
    repeated.stale, repeated.compute_ms, repeated.message = again.reply.stale, again.reply.compute_ms, again.reply.message
    assert again.reply == repeated and "its first answer repeated" in again.reply.message


def test_a_compiled_session_repeats_bit_for_bit_also_across_a_snapshot(framing_only, tmp_path):
    inputs, _, compiled, _ = framing_only
    again, _ = _run("compiled", inputs, tmp_path)
    _same_bits(again, compiled)
    restored, table = _run("compiled", inputs, tmp_path / "restored", snapshot_at=400)
    assert table.get("s").session.rig.compiled  # its cores made again after the snapshot
    _same_bits(restored, compiled)


def test_changes_of_visibility_mode_hand_the_camera_over_without_a_jump(tmp_path):
    """FRAMING_ONLY, then REACTIVE (the deoccluder, compiled too), back, then RAYCAST (the search), back:
    every frame as the Python rig's. The search stays only while it coasts: from frame 436 on it
    chooses among candidates so close that a difference of 1e-14 m in where it starts chooses
    another (so does the Python rig alone, its camera moved 1e-14 m at frame 419), and the two
    paths' FRAMING_ONLY frames differ by that much."""
    styles = {150: pb.REACTIVE, 260: pb.FRAMING_ONLY, 420: pb.RAYCAST, 432: pb.FRAMING_ONLY}
    inputs = _inputs(styles)
    python, _ = _run("python", inputs, tmp_path)
    compiled, table = _run("compiled", inputs, tmp_path)
    flags = {f for a in compiled if a.state is not None for f in a.state.flags}
    assert any(f.startswith("search_") for f in flags)  # the search ran, and handed the camera back
    _agree(compiled, python)
    assert table.get("s").session.rig.compiled  # FRAMING_ONLY again


@pytest.mark.parametrize("name", ["framing_only", "reactive"])
def test_the_suites_toric_recordings_agree_on_both_paths(name, tmp_path):
    """The inputs of the TORIC recordings (tests/data/recordings/) of FRAMING_ONLY and REACTIVE (a
    style change half way) answered on both paths: every frame as above (a pulled REACTIVE camera
    within PULLED_TOL). The search modes' recordings (raycast, anticipation) part at their first near-tie:
    the search's sessions are compared by what they show (the test below), its steps call by call
    (tests/native/test_search_native.py)."""
    entries = list(read_entries(RECORDINGS / f"{name}.cdrec"))
    create, inputs = (
        entries[0].create,
        [getattr(e, e.WhichOneof("entry")) for e in entries[1:] if e.WhichOneof("entry") != "camera"],
    )
    create.record = False
    for msg in inputs:
        msg.session_id = "s"
    python, _ = _run("python", inputs, tmp_path, create=create)
    compiled, table = _run("compiled", inputs, tmp_path, create=create)
    assert isinstance(table.get("s").session.rig, CompiledToricRig) and len(compiled) == 240
    _agree(compiled, python)


@pytest.mark.parametrize("mode", [pb.ANTICIPATION, pb.RAYCAST], ids=["ANTICIPATION", "RAYCAST"])
def test_a_compiled_search_session_repeats_bit_for_bit_and_sees_as_well_as_the_python_one(mode, tmp_path):
    """Whole demo sessions in a search mode, from their first frame: the compiled search (tested
    call by call in tests/native/test_search_native.py) parts from the Python one at its first
    near-tie, so the sessions are compared by what they show: the share of the targets' samples
    seen, over a session, and of its frames that see less than half (VISIBILITY's own estimate,
    by the Scene on the compiled path, by Embree on the Python one).

    After parting, one session's share is a draw: it differs from its Python twin's by up to 0.07
    either way from one demo scene to another, and which way on a given scene depends on the
    machine's Embree (float32, its code chosen by the CPU's instruction set). So the sessions of
    seven scenes are compared pairwise: the compiled path may lose on average no more than
    SEEN_TOL beyond twice the standard error of the pairs' mean (what seven draws cannot tell
    from nothing). It catches a compiled search that sees systematically worse, not one scene's
    luck."""
    inputs = _inputs({1: mode})
    python, _ = _run("python", inputs, tmp_path)
    compiled, _ = _run("compiled", inputs, tmp_path)
    _same_bits(_run("compiled", inputs, tmp_path)[0], compiled)
    restored, table = _run("compiled", inputs, tmp_path / "restored", snapshot_at=400)
    _same_bits(restored, compiled)
    assert isinstance(table.get("s").session.rig, CompiledToricRig)

    def seen(answers: list[Answer]) -> tuple[float, float]:
        visibility = np.array([a.state.visibility for a in answers if a.state is not None])
        return float(visibility.mean()), float((visibility < 0.5).mean())

    pairs = [(seen(python), seen(compiled))]
    for seed in SEEN_SEEDS:
        plain = _inputs({1: mode}, seed=seed, gap=False)
        path = tmp_path / f"seed{seed}"
        pairs.append((seen(_run("python", plain, path, seed=seed)[0]), seen(_run("compiled", plain, path, seed=seed)[0])))
    # (scenes, 2) of the compiled path's gain over the Python one: in the share seen, in poor frames
    gain = np.array([[c_mean - p_mean, p_poor - c_poor] for (p_mean, p_poor), (c_mean, c_poor) in pairs])
    margin = SEEN_TOL + 2.0 * gain.std(axis=0, ddof=1) / math.sqrt(len(gain))
    print(pb.VisibilityMode.Name(mode), "python, compiled (share seen, poor frames) per scene", pairs)
    print("compiled's mean gain", gain.mean(axis=0), "allowed loss", margin)
    assert (gain.mean(axis=0) >= -margin).all()


def test_the_compiled_path_is_the_default_and_the_setting_reaches_the_rig(tmp_path, monkeypatch):
    assert ServerSettings().frame_path == "compiled"
    scene = build_demo_scene(seed=7, duration_s=1.0)
    served: list[ServerSettings] = []
    monkeypatch.setattr(camdirector.front.main, "run", lambda settings: served.append(settings) or 0)
    monkeypatch.setenv("CAMDIRECTOR_DATA_DIR", str(tmp_path))
    assert cli.main(["serve", "--frame-path", "python"]) == 0
    monkeypatch.setenv("CAMDIRECTOR_FRAME_PATH", "python")
    assert cli.main(["serve"]) == 0
    assert cli.main(["serve", "--frame-path", "compiled"]) == 0  # the flag over the environment
    rigs = []
    for settings in [ServerSettings(data_dir=str(tmp_path)), *served]:
        table = SessionTable(settings)
        table.create("s", session_request(scene, Lens()))
        rigs.append(type(table.get("s").session.rig))
        table.close_all()
    assert rigs == [CompiledToricRig, ToricRig, ToricRig, CompiledToricRig]


def test_a_bad_frame_path_is_refused_with_its_values(monkeypatch, capsys):
    with pytest.raises(ValueError, match="frame_path must be one of python, compiled, not 'rust'"):
        ServerSettings(frame_path="rust")
    monkeypatch.setattr(camdirector.front.main, "run", lambda settings: pytest.fail("served with a bad frame path"))
    with pytest.raises(SystemExit):
        cli.main(["serve", "--frame-path", "rust"])
    assert "argument --frame-path: invalid choice: 'rust'" in capsys.readouterr().err
    monkeypatch.setenv("CAMDIRECTOR_FRAME_PATH", "fast")
    with pytest.raises(SystemExit):
        cli.main(["serve"])
    assert "frame_path must be one of python, compiled, not 'fast'" in capsys.readouterr().err
